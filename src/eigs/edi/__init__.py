"""Event binning and EDI latent sharp frames."""
