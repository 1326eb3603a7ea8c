# Evaluation: one folder per run folder, results/{scene}/b{B}/eval/{run}/ (metrics.json, per_image.csv, renders/).
# Synthetic scenes are scored at the test cameras of sfm/test_cameras.h5 against their ground truth; scenes without
# ground truth by BRISQUE on the training views and a render path (config `evaluate: path_frames`); simulated
# recordings through the real-data path with a hidden ground truth (config/davis346.yaml) both ways. docs/evaluation.md.


rule evaluate:
    input:
        model=run_model,
        config=run_path(run_folder.CONFIG),
        scene="results/{scene}/scene.h5",
        sfm="results/{scene}/b{bins}/sfm",
        lpips="resources/lpips/MANIFEST.json",
        brisque="resources/brisque/MANIFEST.json",
    output:
        metrics="results/{scene}/b{bins}/eval/{run}/metrics.json",
        per_image="results/{scene}/b{bins}/eval/{run}/per_image.csv",
        renders=directory("results/{scene}/b{bins}/eval/{run}/renders"),
    wildcard_constraints:
        scene=names_regex(ALL_SCENES),
        bins=r"\d+",
        run=names_regex(sorted(RUNS)),
    params:
        run_dir=lambda wc, input: os.path.dirname(input.model),
        resources=lambda wc, input: os.path.dirname(os.path.dirname(input.lpips)),
        options=evaluate_options,
    log:
        "logs/evaluate/{scene}_b{bins}_{run}.log",
    benchmark:
        "benchmarks/evaluate/{scene}_b{bins}_{run}.tsv"
    threads: 1
    resources:
        mem_mb=3000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs evaluate {params.run_dir} {input.scene} {input.sfm} -o {output.metrics} {params.options} "
        "--resources {params.resources} --threads {threads} > {log} 2>&1"


rule all_evaluate:
    input:
        eval_targets(),


STAGE_TARGETS.extend(rules.all_evaluate.input)
