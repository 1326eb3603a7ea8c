# Benchmarks: `snakemake --cores N bench` (not part of `all`; helpers in rules/common_bench.smk). Each script in
# bench/ runs as a job writing its section (NAME.md) and measurements (NAME.json) to results/bench/; bench_report
# assembles them with figures into docs/benchmarks.md, or, in quick mode (`--config bench_quick=1`), into
# results/bench/benchmarks.md, leaving docs/benchmarks.md alone. Every bench job asks for 2 threads (BENCH_THREADS),
# so with --cores 2 no two timings overlap; the scripts set their own thread counts (their sections say which). The
# jobs call the scripts of this checkout's bench/ folder (python, not the eigs CLI): they run here, not on a cluster.


rule bench_script:
    output:
        md="results/bench/{name}.md",
        json="results/bench/{name}.json",
    wildcard_constraints:
        name=names_regex(BENCH_SCRIPTS),
    params:
        script=lambda wc: os.path.join(BENCH_DIR, f"{wc.name}.py"),
        args=lambda wc: bench_args(wc.name),
        out=lambda wc, output: os.path.dirname(output.md),
    log:
        "logs/bench/{name}.log",
    benchmark:
        "benchmarks/bench/{name}.tsv"
    threads: BENCH_THREADS
    resources:
        mem_mb=8000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "EIGS_PROGRESS=0 python {params.script} --out {params.out} {params.args} > {log} 2>&1"


# The image metrics need the LPIPS/BRISQUE model files of rule resources.
rule bench_metrics:
    input:
        rules.resources.output,
    output:
        md="results/bench/metrics.md",
        json="results/bench/metrics.json",
    params:
        script=os.path.join(BENCH_DIR, "metrics.py"),
        args=f"--resources resources {bench_args('metrics')}",
        out=lambda wc, output: os.path.dirname(output.md),
    log:
        "logs/bench/metrics.log",
    benchmark:
        "benchmarks/bench/metrics.tsv"
    threads: BENCH_THREADS
    resources:
        mem_mb=8000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "EIGS_PROGRESS=0 python {params.script} --out {params.out} {params.args} > {log} 2>&1"


# One training step of every method, on the EDI/SfM/init artifacts of one configured scene.
rule bench_train:
    input:
        scene=lambda wc: f"results/{bench_train_scene()}/scene.h5",
        edi=lambda wc: f"results/{bench_train_scene()}/b{edi_bins()[0]}/edi.h5",
        sfm=lambda wc: f"results/{bench_train_scene()}/b{edi_bins()[0]}/sfm",
        init=lambda wc: f"results/{bench_train_scene()}/b{edi_bins()[0]}/init.ply",
    output:
        md=["results/bench/train-step.md", "results/bench/train-step-methods.md", "results/bench/train-step-malloc.md"],
        json=[
            "results/bench/train-step.json",
            "results/bench/train-step-methods.json",
            "results/bench/train-step-malloc.json",
        ],
    params:
        script=os.path.join(BENCH_DIR, "train.py"),
        results=lambda wc, input: os.path.dirname(input.scene),
        bins=edi_bins()[0],
        quick="--quick" if BENCH_QUICK else "",
    log:
        "logs/bench/train.log",
    benchmark:
        "benchmarks/bench/train.tsv"
    threads: BENCH_THREADS
    resources:
        mem_mb=8000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "EIGS_PROGRESS=0 python {params.script} --results {params.results} --bins {params.bins} --threads 2 "
        "{params.quick} --out results/bench > {log} 2>&1"


rule bench_report:
    input:
        expand("results/bench/{name}.json", name=BENCH_SCRIPTS),
        rules.bench_metrics.output,
        rules.bench_train.output,
    output:
        doc=BENCH_DOC,
        figures=report(
            expand(f"{BENCH_FIGURES}/bench_{{f}}.png", f=["edi", "sfm", "rasterizer", "train"]),
            caption="../workflow/report/bench.rst",
            category="Benchmarks",
        ),
        skips=report(f"{BENCH_FIGURES}/bench_skips.png", caption="../workflow/report/skips.rst", category="Benchmarks"),
    params:
        script=os.path.join(BENCH_DIR, "report.py"),
        quick="--quick" if BENCH_QUICK else "",
        facts=bench_facts(),
        figures=lambda wc, output: os.path.dirname(output.skips),
    log:
        "logs/bench/report.log",
    benchmark:
        "benchmarks/bench/report.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "python {params.script} results/bench -o {output.doc} --figures {params.figures} {params.quick} "
        "--facts {params.facts} > {log} 2>&1"


rule bench:
    input:
        rules.bench_report.output,
