"""Event-informed demand prediction (paper §4.2): embeddings, clustering, networks, forecasts.

This package is the only one in surge that imports torch, and it does so lazily:
importing ``predictor`` (or ``predictor.cli``) pulls in nothing heavy.  The torch
code lives in :mod:`predictor.nets`, :mod:`predictor.train` and
:mod:`predictor.forecast`; the embedding model is loaded by :mod:`predictor.embed`
only when texts actually need embedding (the on-disk cache answers otherwise).

Modules
-------
embed       sentence embeddings with an on-disk cache (torch only inside ``Embedder.model``)
cluster     spectral clustering of review embeddings -> R_w (numpy/scikit-learn)
features    temporal/weather/sector features and the sector event feature F_s
dataset     builds the year's training and test arrays from a demand world
nets        the feed-forward networks (torch)
train       training with per-epoch checkpoints and resume (torch)
evaluate    the paper's percent-error ablation (event system, standard NN, previous hour)
assign      demand assignment: occupancy-based rho/delta and historical beta
forecast    ModelForecaster / load_forecaster for the rollout agents
cli         ``surge predictor train|eval``
"""

__all__ = ["__version__"]

__version__ = "0.1.0"
