"""Problems bundled with rfverify (see :func:`rfverify.io.bundled_problems` and README.md here)."""
