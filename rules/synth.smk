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


# A built-in scene written as a user's recording: the E²NeRF real (LLFF) layout, with its ground truth beside it
# (docs/synthetic.md, "E²NeRF real layout"). The scene's `source:` (results/<scene>/e2nerf-real) is read back by
# the ingest rule like any E²NeRF real scene; `--groundtruth results/<scene>/groundtruth.h5` merges the truth.
SIMULATED_SCENES = plan.simulated_scenes(config)
for _name in SIMULATED_SCENES:
    if SCENES[_name].get("source") != f"results/{_name}/e2nerf-real" or SCENES[_name].get("format") != "e2nerf-real":
        raise ValueError(f"scene {_name}: a simulate: scene needs source results/{_name}/e2nerf-real, format e2nerf-real")


rule synth_e2nerf_real:
    output:
        layout=directory("results/{scene}/e2nerf-real"),
        groundtruth="results/{scene}/groundtruth.h5",
    wildcard_constraints:
        scene=names_regex(SIMULATED_SCENES),
    params:
        builtin=lambda wc: SCENES[wc.scene]["simulate"]["builtin"],
        config=lambda wc: config_json(SCENES[wc.scene]["simulate"].get("overrides", {})),
        image_format=lambda wc: SCENES[wc.scene]["simulate"].get("image_format", "jpg"),
    log:
        "logs/synth/{scene}.log",
    benchmark:
        "benchmarks/synth/{scene}.tsv"
    threads: threads_for("synth")
    resources:
        mem_mb=8000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs synth --scene {params.builtin} --config {params.config} --e2nerf-real-layout {output.layout} "
        "--groundtruth-out {output.groundtruth} --image-format {params.image_format} --threads {threads} "
        "> {log} 2>&1"
