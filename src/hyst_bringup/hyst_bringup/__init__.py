"""hyst_bringup: the top of the hyst packages, the one that may import all the others.

What puts packages together lives here, so that none of them needs another beside it: the device emulator on the
simulated plant (:mod:`hyst_bringup.emulator`, the ``hyst_emulator`` command). See docs/ARCHITECTURE.md.
"""
import hyst_common  # noqa: F401  first: sets single-threaded BLAS before numpy loads (hyst_common.blas)
