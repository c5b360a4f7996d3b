"""Identification of MMG coefficients: strategies of one interface (`base.Identification`),
by gradient on the multi-step loss and by Levenberg-Marquardt on the multi-step residuals."""
