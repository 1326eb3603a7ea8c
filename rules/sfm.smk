# Camera poses of every EDI latent frame (COLMAP or given poses) and the initial Gaussians.


# One rule definition for the three ways a scene gets its poses (common.smk define_sfm_rule; eigs.plan.sfm_rule picks
# one per scene): sfm (COLMAP), sfm_given (ground-truth poses of a built-in scene), sfm_model (an existing COLMAP model)
define_sfm_rule("sfm", SFM_COLMAP_SCENES, {}, "")
define_sfm_rule("sfm_given", SFM_GIVEN_SCENES, {}, "--mode given ")
define_sfm_rule("sfm_model", SFM_MODEL_SCENES, {"model": sfm_model_path}, "--mode model --model {input.model} ")


# A COLMAP scene at any B but the first (`sfm: share_across_bins`, eigs.plan.sfm_shares_bins): the first B's SfM read
# at this B's latent times, its points and test cameras copied (eigs.sfm.resample); the rule `sfm` above then runs
# for the first B only (the ruleorder settles the other B).
ruleorder: sfm_resample > sfm


rule sfm_resample:
    input:
        scene="results/{scene}/scene.h5",
        edi="results/{scene}/b{bins}/edi.h5",
        base=sfm_base,
    output:
        directory("results/{scene}/b{bins}/sfm"),
    wildcard_constraints:
        scene=names_regex(SFM_SHARED_SCENES),
        bins=names_regex([str(b) for b in edi_bins() if b != SFM_BASE_BINS]),
    params:
        config=sfm_config,
    log:
        "logs/sfm/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/sfm/{scene}_b{bins}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs sfm {input.scene} {input.edi} -o {output} --config {params.config} --mode resample --from {input.base} "
        "--threads 1 > {log} 2>&1"


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
