"""Identification: the `Trainer` (gradient training of MMG-only, NN-only and hybrid models)
composed of its parts (windows, losses, the training loop with its checkpointing and
logging parts, the warm start), the identification strategies of `sysid.identify.solvers`
(gradient and Levenberg-Marquardt), the uncertainty of identified coefficients, seeds side
by side and the preprocessing-bias replay."""
