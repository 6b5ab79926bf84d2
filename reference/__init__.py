"""Independent arbitrary-precision (mpmath) reference implementation of Algorithm 1.

Not implemented yet: filled by the reference-implementation issue (DESIGN §5).  By design
this package must not import rfverify's numerics; it may use rfverify's problem container and
file I/O only.
"""
