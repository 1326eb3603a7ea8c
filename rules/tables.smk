# The paper's Tables I-V and the figures from every evaluated run. Which run fills which row: the config's
# `tables:` section (row key -> run name, defaults in eigs.tables.rows); rows whose run is not in `runs:` show the paper's
# values only. docs/evaluation.md.


rule tables:
    input:
        metrics=eval_targets(),
    output:
        csv=report(
            expand("results/tables/{t}.csv", t=TABLE_NAMES),
            caption="../workflow/report/tables.rst",
            category="Tables",
        ),
        md=expand("results/tables/{t}.md", t=TABLE_NAMES),
        tex=expand("results/tables/{t}.tex", t=TABLE_NAMES),
        extra=expand("results/tables/{t}.{ext}", t=EXTRA_TABLES, ext=("csv", "md")),
        all_md="results/tables/tables.md",
        per_scene="results/tables/per_scene.csv",
    params:
        tables=tables_json(),
        out=lambda wc, output: os.path.dirname(output.all_md),
    log:
        "logs/tables.log",
    benchmark:
        "benchmarks/tables.tsv"
    threads: 1
    resources:
        mem_mb=1000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs tables {input.metrics} --tables {params.tables} -o {params.out} > {log} 2>&1"


rule figures:
    input:
        metrics=eval_targets(),
        extra=figure_inputs,
    output:
        grids=report(
            expand("results/figures/qualitative_{scene}.png", scene=figure_scenes()),
            caption="../workflow/report/qualitative.rst",
            category="Figures",
        ),
        curves=report("results/figures/curves.png", caption="../workflow/report/curves.rst", category="Figures"),
        pareto=report("results/figures/pareto.png", caption="../workflow/report/pareto.rst", category="Figures"),
    params:
        grid_runs=grid_runs(),
        out=lambda wc, output: os.path.dirname(output.pareto),
    log:
        "logs/figures.log",
    benchmark:
        "benchmarks/figures.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs figures {input.metrics} --grid-runs {params.grid_runs} -o {params.out} > {log} 2>&1"


rule all_tables:
    input:
        rules.tables.output,
        rules.figures.output,


if RUNS:  # tables and figures need at least one run
    STAGE_TARGETS.extend(rules.all_tables.input)
