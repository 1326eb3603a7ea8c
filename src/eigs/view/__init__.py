"""``eigs view``: trained Gaussian runs in a local 3D viewer in the browser (viser; docs/viewer.md).

:mod:`eigs.view.scene` turns run folders into what the viewer shows (splats, cameras, run discovery) with numpy
only; :mod:`eigs.view.server` serves them with viser; :mod:`eigs.view.cli` is the subcommand.
"""
