"""Work-precision measurements and the ``model: auto`` choice made from them."""
