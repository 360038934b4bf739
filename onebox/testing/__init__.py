"""Helpers that the tests and the benchmarks share: synthetic scenes, fake captures, running
commands and reading their output, free ports, the committed capture.

Shipped with the library, as ``numpy.testing`` is, so a benchmark can use them without
importing ``tests/``.
"""
