"""The training tests use the toy-scene artifacts of tests/conftest.py (``toy``)."""
