"""Plain-Python reference implementations the tests compare the compiled code with
(written from the docstrings, independently of the kernels; not part of the product)."""
