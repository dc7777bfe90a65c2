"""Event-informed demand prediction (paper §4.2): embeddings, clustering, networks, forecasts.

This package is the only one in surge that imports torch, and it does so lazily:
importing ``predictor`` (or ``coordinator.cli.predictor``) pulls in nothing heavy.  The torch
code lives in :mod:`predictor.nets`, :mod:`predictor.train` and
:mod:`predictor.forecaster`; the embedding model is loaded by :mod:`predictor.embed`
only when texts actually need embedding (the on-disk cache answers otherwise).

Modules
-------
embed       sentence embeddings with an on-disk cache (torch only inside ``Embedder.model``)
cluster     spectral clustering of review embeddings -> R_w (numpy/scikit-learn)
features    temporal/weather/sector features and the sector event feature F_s
dataset     the year's arrays from a demand world; the train/validation/test split
nets        the feed-forward networks (torch)
train       training with early stopping on validation loss, checkpoints and resume (torch)
evaluate    the ablation: standard, metadata, shuffled-text and event networks, noise floor,
            previous hour; percent error per hour with bootstrap CIs
inputs      the world and user files (events, reviews, trips) a model was trained with
assign      demand assignment: occupancy-based rho/delta and historical beta
forecast    ModelForecaster / load_forecaster for the rollout agents
cli         ``surge predictor train|eval|serve``
"""

__all__ = ["__version__"]

__version__ = "0.1.0"
