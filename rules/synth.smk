# Built-in synthetic scenes (independent ray caster, camera shake, event simulator, ground truth).


rule synth:
    output:
        scene="results/{scene}/scene.h5",
        sheet="results/{scene}/contact_sheet.png",
    wildcard_constraints:
        scene=names_regex(BUILTIN_SCENES),
    params:
        builtin=synth_builtin,
        config=synth_config,
    log:
        "logs/synth/{scene}.log",
    benchmark:
        "benchmarks/synth/{scene}.tsv"
    threads: threads_for("synth")
    resources:
        mem_mb=4000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs synth --scene {params.builtin} --config {params.config} "
        "-o {output.scene} --contact-sheet {output.sheet} --threads {threads} > {log} 2>&1"


rule all_synth:
    input:
        expand("results/{scene}/scene.h5", scene=BUILTIN_SCENES),


STAGE_TARGETS.extend(rules.all_synth.input)
