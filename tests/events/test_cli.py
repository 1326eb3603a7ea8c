"""`eigs edi` end to end on a small simulated scene file: artifact, PNG names, errors."""

from __future__ import annotations

import numpy as np

from eigs.artifacts.edi import latent_png_name, parse_latent_png_name, read_edi
from eigs.cli import main
from eigs.scene import write_scene
from tests.events.sim import make_scene


def test_cli_end_to_end(tmp_path, capsys):
    scene, _ = make_scene(n_views=2, h=32, w=40, seed=1)
    sp = tmp_path / "scene.h5"
    write_scene(scene, sp)
    out = tmp_path / "b2" / "edi.h5"
    lat = tmp_path / "b2" / "latent"
    assert main(["edi", str(sp), "-o", str(out), "--latent-dir", str(lat), "--bins", "2", "--threads", "1"]) == 0
    res = read_edi(out)
    assert res.mode == "estimated" and res.n_bins == 2 and res.latent.shape == (2, 3, 32, 40, 3)
    assert res.event_mask is not None and res.event_mask.shape == (32, 40)
    names = sorted(p.name for p in lat.iterdir())
    assert names == sorted(latent_png_name(v, k) for v in range(2) for k in range(3))
    assert parse_latent_png_name(names[-1]) == (1, 2)
    # cum_counts between latent times are the binned events
    ev = scene.events
    a, b = ev.view_index[1]
    sel = (ev.t[a:b] >= res.timestamps_us[1, 0]) & (ev.t[a:b] < res.timestamps_us[1, 2])
    np.testing.assert_array_equal(
        res.cum_counts[1, 2].sum(), ev.p[a:b][sel].astype(np.int64).sum()
    )
    # bad input → one-line error, exit 2
    assert main(["edi", str(sp), "-o", str(out), "--bins", "0"]) == 2
    assert "--bins" in capsys.readouterr().err
    assert main(["edi", str(tmp_path / "missing.h5"), "-o", str(out)]) == 2
