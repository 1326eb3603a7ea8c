from tests.metrics.conftest import resources_dir  # noqa: F401  (the LPIPS/BRISQUE model files fixture)
