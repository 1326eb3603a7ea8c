# Helpers of rules/video.smk (the orbit videos); needs rules/common.smk. Which runs and scenes: eigs.plan.


def video_runs():
    """The runs a video shows, in order: `video: runs:`, else the default rows' (eigs.plan.video_runs)."""
    return plan.video_runs(config)


def video_scene_runs(scene):
    """The video runs trained on `scene`, in order."""
    return [r for r in video_runs() if scene in run_scenes(r)]


VIDEO_SCENES = plan.video_scenes(config)


def video_inputs(wildcards):
    """Model file and config.json of each of the scene's video runs, and the SfM folder its cameras come from."""
    out = []
    for run in video_scene_runs(wildcards.scene):
        d = f"results/{wildcards.scene}/b{run_bins(run)}"
        out += [f"{d}/{run}/{run_model_file(run)}", f"{d}/{run}/{run_folder.CONFIG}", f"{d}/sfm"]
    return sorted(set(out))


def video_run_dirs(wildcards):
    return " ".join(
        shlex.quote(f"results/{wildcards.scene}/b{run_bins(r)}/{r}") for r in video_scene_runs(wildcards.scene)
    )


def video_options(wildcards):
    """`eigs video` flags from the `video:` section (unset: VideoOptions' defaults)."""
    v = config.get("video", {})
    return " ".join(f"--{k} {v[k]}" for k in ("frames", "fps") if k in v)
