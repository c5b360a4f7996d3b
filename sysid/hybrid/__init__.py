"""Learned force terms beside the physics: the FNN correction (`correction`), the kNN
out-of-distribution gate (`knn_gate`), MMG-only, NN-only and hybrid force models behind one
interface (`force_models`) and mean-of-members ensembles (`ensemble`)."""
