# EDI latent sharp frames: binning, E²NeRF or estimated mode, latent PNGs for SfM (keyed by the number of bins).


rule edi:
    input:
        "results/{scene}/scene.h5",
    output:
        edi="results/{scene}/b{bins}/edi.h5",
        latent=directory("results/{scene}/b{bins}/latent"),
    wildcard_constraints:
        scene=names_regex(EVENT_SCENES),
        bins=r"\d+",
    params:
        config=edi_config,
    log:
        "logs/edi/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/edi/{scene}_b{bins}.tsv"
    threads: threads_for("edi")
    resources:
        mem_mb=4000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs edi {input} -o {output.edi} --latent-dir {output.latent} --bins {wildcards.bins} "
        "--config {params.config} --threads {threads} > {log} 2>&1"


# Scenes configured with `events: false` (common.smk FRAMES_ONLY_SCENES): the same artifact without the events
# (`eigs edi --no-events`: every view passed through as sharp, no binning or threshold search; docs/edi.md), so
# SfM, init and the frames-only methods read it unchanged; the methods that need events are not scheduled there.
rule edi_frames:
    input:
        "results/{scene}/scene.h5",
    output:
        edi="results/{scene}/b{bins}/edi.h5",
        latent=directory("results/{scene}/b{bins}/latent"),
    wildcard_constraints:
        scene=names_regex(FRAMES_ONLY_SCENES),
        bins=r"\d+",
    params:
        config=edi_config,
    log:
        "logs/edi_frames/{scene}_b{bins}.log",
    benchmark:
        "benchmarks/edi_frames/{scene}_b{bins}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs edi {input} -o {output.edi} --latent-dir {output.latent} --bins {wildcards.bins} "
        "--config {params.config} --no-events --threads {threads} > {log} 2>&1"


rule all_edi:
    input:
        expand("results/{scene}/b{bins}/edi.h5", scene=sorted(SCENES), bins=edi_bins()),


STAGE_TARGETS.extend(rules.all_edi.input)
