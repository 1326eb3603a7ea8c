# Training: one run folder per (scene, B, run name); a run name stands for a method and its resolved options
# (config `runs:`), so a run shared by several tables is trained once. A job asks for one GPU; Snakemake caps it at
# the available amount (the default profile's `gpu: 0` on CPU machines), and `eigs train --device auto` follows
# what the job got (CUDA when a GPU is visible, else the CPU). One rule for both trainer families, the same command;
# its two names differ in the model file only (eigs.artifacts.run): `train` for the Gaussian runs (model.ply) and
# `train_field` for the radiance-field runs (common.smk FIELD_RUNS: nerf, deblur-nerf, edi-nerf, e2nerf; model.npz).

for _name, _model, _runs in (
    ("train", run_folder.MODEL_PLY, GAUSSIAN_RUNS),
    ("train_field", run_folder.MODEL_NPZ, FIELD_RUNS),
):

    rule:
        name:
            _name
        input:
            scene="results/{scene}/scene.h5",
            edi="results/{scene}/b{bins}/edi.h5",
            sfm="results/{scene}/b{bins}/sfm",
            init="results/{scene}/b{bins}/init.ply",
        output:
            model=run_path(_model),
            config=run_path(run_folder.CONFIG),
            log=run_path(run_folder.LOG),
        wildcard_constraints:
            scene=names_regex(ALL_SCENES),
            bins=r"\d+",
            run=names_regex(_runs),
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
