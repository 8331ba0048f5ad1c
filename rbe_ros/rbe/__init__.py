"""The RBE model: equilibrium matrices, friction cones, the conic solve and its results."""
