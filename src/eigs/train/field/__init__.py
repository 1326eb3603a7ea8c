"""The radiance-field methods (a voxel-grid field, ``model.npz``): the field model, the trainer's hooks on the shared
loop (:mod:`eigs.train.loop`), the methods and, torch-free, their options (:mod:`eigs.train.field.options`, what the
catalog imports). This package's ``__init__`` imports nothing."""
