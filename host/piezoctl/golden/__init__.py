"""Bit-exact golden models of the firmware core kernels.

Each module here computes, with Python integers or numpy int64, exactly the
integers the C kernel of the same name computes, and can export golden vectors
as a C header for the cmocka tests (``python -m piezoctl.golden.export KERNEL``).
"""
