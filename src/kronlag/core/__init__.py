"""What every layer of kronlag stands on: the exceptions and warnings (:mod:`~kronlag.core.errors`)
and the one route from symbolic expressions to numbers (:mod:`~kronlag.core.kernels`)."""
