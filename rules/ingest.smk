# User data: E²NeRF layouts, HDF5 / text / AEDAT4 event files -> scene file (docs/ingestion.md).
# The scene is named after its config key; config `options` come after, so they may override --name.
# Each option is shell-quoted, so paths with spaces survive.
import shlex


rule ingest:
    input:
        ingest_source,
    output:
        scene="results/{scene}/scene.h5",
    wildcard_constraints:
        scene=names_regex(INGESTED_SCENES),
    params:
        format=ingest_format,
        options=lambda wc: " ".join(shlex.quote(str(o)) for o in SCENES[wc.scene].get("options", [])),
    log:
        "logs/ingest/{scene}.log",
    benchmark:
        "benchmarks/ingest/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=8000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs ingest --format {params.format} --name {wildcards.scene} {params.options} {input:q} "
        "-o {output.scene} > {log} 2>&1"


rule all_ingest:
    input:
        expand("results/{scene}/scene.h5", scene=INGESTED_SCENES),


STAGE_TARGETS.extend(rules.all_ingest.input)
