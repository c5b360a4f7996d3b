"""Identification: the `Trainer` (gradient training of MMG-only, NN-only and hybrid models),
Levenberg-Marquardt identification of MMG coefficients, their uncertainty, training
checkpoints and the preprocessing-bias replay."""
