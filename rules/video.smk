# Orbit videos: per scene one H.264 MP4 of the video runs rendered side by side along a camera path around the
# scene (`eigs video`, eigs.view.video; docs/evaluation.md). Which runs: the config's `video: runs:`, else the Table I
# rows of eigs.view.video.VideoOptions.table1_rows that have a configured run (3dgs, edi-3dgs, eigs, eigs+, oracle).


rule video:
    input:
        runs=video_inputs,
        scene="results/{scene}/scene.h5",
    output:
        report("results/videos/{scene}.mp4", caption="../workflow/report/video.rst", category="Videos"),
    wildcard_constraints:
        scene=names_regex(VIDEO_SCENES),
    params:
        runs=video_run_dirs,
        options=video_options,
    log:
        "logs/video/{scene}.log",
    benchmark:
        "benchmarks/video/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=3000,
    conda:
        "../workflow/envs/eigs.yaml"
    shell:
        "eigs video {params.runs} --scene {input.scene} -o {output} {params.options} --threads {threads} > {log} 2>&1"


rule all_video:
    input:
        expand("results/videos/{scene}.mp4", scene=VIDEO_SCENES),


STAGE_TARGETS.extend(rules.all_video.input)
