"""Analyses built on the RBE solve, in layers: options and the geometry stage (assembly,
validate), the contact graph and the steps of a sequence, the verdict of one assembly, the
analyses that use it (holds, incremental per-step checks, tilt, minimum friction, virtual
interfaces), the pipeline (check_scene, check_sequence, check_state) and planning."""
