"""The Gaussian methods (a 3DGS model, ``model.ply``): the model and its densification, the trainer's hooks on the
shared loop (:mod:`eigs.train.loop`), the methods and, torch-free, their options (:mod:`eigs.train.gaussian.options`,
what the catalog imports). This package's ``__init__`` imports nothing."""
