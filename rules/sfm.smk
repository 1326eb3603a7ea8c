# Camera poses of every EDI latent frame (COLMAP or given poses) and the initial Gaussians.


rule sfm:
    input:
        scene="results/{scene}/scene.h5",
        edi="results/{scene}/b{bins}/edi.h5",
        latent="results/{scene}/b{bins}/latent",
    output:
        directory("results/{scene}/b{bins}/sfm"),
    wildcard_constraints:
        scene=names_regex(SFM_COLMAP_SCENES),
        bins=r"\d+",
    params:
        config=sfm_config,
    log:
        "logs/sfm/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/sfm/{scene}_b{bins}.tsv"
    threads: threads_for("sfm")
    resources:
        mem_mb=6000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs sfm {input.scene} {input.edi} --latent-dir {input.latent} -o {output} --config {params.config} "
        "--threads {threads} > {log} 2>&1"


# Built-in scenes with ground-truth poses allowed (common.smk SFM_GIVEN_SCENES): the same stage in given mode, no
# COLMAP mapping (triangulation at the given poses for the initial points; docs/sfm.md).
rule sfm_given:
    input:
        scene="results/{scene}/scene.h5",
        edi="results/{scene}/b{bins}/edi.h5",
        latent="results/{scene}/b{bins}/latent",
    output:
        directory("results/{scene}/b{bins}/sfm"),
    wildcard_constraints:
        scene=names_regex(SFM_GIVEN_SCENES),
        bins=r"\d+",
    params:
        config=sfm_config,
    log:
        "logs/sfm/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/sfm/{scene}_b{bins}.tsv"
    threads: threads_for("sfm")
    resources:
        mem_mb=6000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs sfm {input.scene} {input.edi} --latent-dir {input.latent} -o {output} --config {params.config} "
        "--mode given --threads {threads} > {log} 2>&1"


# Scenes whose poses come from an existing COLMAP model (`sfm: {mode: model, path: DIR}`, globally or per scene;
# common.smk SFM_MODEL_SCENES): no COLMAP mapping; the model's poses, matched to the views by name (docs/sfm.md).
rule sfm_model:
    input:
        scene="results/{scene}/scene.h5",
        edi="results/{scene}/b{bins}/edi.h5",
        latent="results/{scene}/b{bins}/latent",
        model=sfm_model_path,
    output:
        directory("results/{scene}/b{bins}/sfm"),
    wildcard_constraints:
        scene=names_regex(SFM_MODEL_SCENES),
        bins=r"\d+",
    params:
        config=sfm_config,
    log:
        "logs/sfm/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/sfm/{scene}_b{bins}.tsv"
    threads: threads_for("sfm")
    resources:
        mem_mb=6000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs sfm {input.scene} {input.edi} --latent-dir {input.latent} -o {output} --config {params.config} "
        "--mode model --model {input.model} --threads {threads} > {log} 2>&1"


rule init:
    input:
        "results/{scene}/b{bins}/sfm",
    output:
        "results/{scene}/b{bins}/init.ply",
    wildcard_constraints:
        scene=names_regex(ALL_SCENES),
        bins=r"\d+",
    params:
        config=init_config,
    log:
        "logs/init/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/init/{scene}_b{bins}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs init {input} -o {output} --config {params.config} > {log} 2>&1"


rule all_sfm:
    input:
        expand("results/{scene}/b{bins}/sfm", scene=ALL_SCENES, bins=edi_bins()),
        expand("results/{scene}/b{bins}/init.ply", scene=ALL_SCENES, bins=edi_bins()),


STAGE_TARGETS.extend(rules.all_sfm.input)
