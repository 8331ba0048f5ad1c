"""Analyses built on the RBE solve: the stability check and the per-step sequence check."""
