"""Benchmark problems with references independent of kronlag's integrators.

:mod:`kronlag.benchmarks.iftomm` holds the IFToMM multibody benchmark library,
problem set A (A01-A05): parameter values, initial states, time spans, each
benchmark's own error measure and its reference.
"""

from . import iftomm

__all__ = ["iftomm"]
