"""Independent references for the tests: computations that share no code with rbe_ros.

``mass``: volume, mass and centroid of a block from its scene description (divergence
theorem over the faces); ``arch_limit``: the exact stability limits of the semicircular arch
by a thrust-line LP; ``plane_blocks``: the equilibrium of plane block assemblies (arches on
buttresses, step by step, with holds) by joint end forces, built from the generators'
documented dimensions; ``stacks``: the closed-form verdict of a stack of boxes (the overhang
condition). Benchmarks use them too (benchmarks/bench.py).
"""
