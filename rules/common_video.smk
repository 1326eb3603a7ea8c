# Helpers of rules/video.smk (the orbit videos); needs rules/common.smk and rules/common_tables.smk (TABLE_ROWS).
from eigs.view.video import VideoOptions


def video_runs():
    """The runs a video shows, in order: `video: runs:` (each must be a `runs:` entry), else the default rows'."""
    given = config.get("video", {}).get("runs")
    if given is not None:
        unknown = [r for r in given if r not in RUNS]
        if unknown:
            raise ValueError(f"config: video: runs {', '.join(unknown)} are not in `runs:`")
        return list(dict.fromkeys(given))
    table1 = TABLE_ROWS["table1"]
    return list(dict.fromkeys(table1[k] for k in VideoOptions().table1_rows if table1.get(k) in RUNS))


def video_scene_runs(scene):
    """The video runs trained on `scene`, in order."""
    return [r for r in video_runs() if scene in run_scenes(r)]


VIDEO_SCENES = sorted({s for r in video_runs() for s in run_scenes(r)})


def video_inputs(wildcards):
    """Model file and config.json of each of the scene's video runs, and the SfM folder its cameras come from."""
    out = []
    for run in video_scene_runs(wildcards.scene):
        d = f"results/{wildcards.scene}/b{run_bins(run)}"
        out += [f"{d}/{run}/{run_model_file(run)}", f"{d}/{run}/config.json", f"{d}/sfm"]
    return sorted(set(out))


def video_run_dirs(wildcards):
    return " ".join(
        shlex.quote(f"results/{wildcards.scene}/b{run_bins(r)}/{r}") for r in video_scene_runs(wildcards.scene)
    )


def video_options(wildcards):
    """`eigs video` flags from the `video:` section (unset: VideoOptions' defaults)."""
    v = config.get("video", {})
    return " ".join(f"--{k} {v[k]}" for k in ("frames", "fps") if k in v)
