# Training: one run folder per (scene, B, run name); a run name stands for a method and its resolved options
# (config `runs:`), so a run shared by several tables is trained once. A job asks for one GPU; Snakemake caps it at
# the available amount (the default profile's `gpu: 0` on CPU machines), and `eigs train --device auto` follows
# what the job got (CUDA when a GPU is visible, else the CPU). Field runs (common.smk FIELD_RUNS) write model.npz
# instead of model.ply and so have their own rule, train_field.


rule train:
    input:
        scene="results/{scene}/scene.h5",
        edi="results/{scene}/b{bins}/edi.h5",
        sfm="results/{scene}/b{bins}/sfm",
        init="results/{scene}/b{bins}/init.ply",
    output:
        model="results/{scene}/b{bins}/{run}/model.ply",
        config="results/{scene}/b{bins}/{run}/config.json",
        log="results/{scene}/b{bins}/{run}/train_log.csv",
    wildcard_constraints:
        scene=names_regex(ALL_SCENES),
        bins=r"\d+",
        run=names_regex(GAUSSIAN_RUNS),
    params:
        config=train_config_json,
        run_dir=lambda wc, output: os.path.dirname(output.model),
    log:
        "logs/train/{scene}_b{bins}_{run}.log",
    benchmark:
        "benchmarks/train/{scene}_b{bins}_{run}.tsv"
    threads: threads_for("train")
    resources:
        mem_mb=4000,
        gpu=1,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs train {input.scene} {input.edi} {input.sfm} {input.init} -o {params.run_dir} "
        "--config {params.config} --threads {threads} > {log} 2>&1"


# The radiance-field methods (nerf, deblur-nerf, edi-nerf, e2nerf): the same command; the model file is model.npz.
rule train_field:
    input:
        scene="results/{scene}/scene.h5",
        edi="results/{scene}/b{bins}/edi.h5",
        sfm="results/{scene}/b{bins}/sfm",
        init="results/{scene}/b{bins}/init.ply",
    output:
        model="results/{scene}/b{bins}/{run}/model.npz",
        config="results/{scene}/b{bins}/{run}/config.json",
        log="results/{scene}/b{bins}/{run}/train_log.csv",
    wildcard_constraints:
        scene=names_regex(ALL_SCENES),
        bins=r"\d+",
        run=names_regex(FIELD_RUNS),
    params:
        config=train_config_json,
        run_dir=lambda wc, output: os.path.dirname(output.model),
    log:
        "logs/train/{scene}_b{bins}_{run}.log",
    benchmark:
        "benchmarks/train/{scene}_b{bins}_{run}.tsv"
    threads: threads_for("train")
    resources:
        mem_mb=4000,
        gpu=1,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs train {input.scene} {input.edi} {input.sfm} {input.init} -o {params.run_dir} "
        "--config {params.config} --threads {threads} > {log} 2>&1"


rule all_train:
    input:
        train_targets(),


STAGE_TARGETS.extend(rules.all_train.input)
