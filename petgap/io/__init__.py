"""What goes in and out of a run: the scene schema (``scene``, TOML files) and
the result files (``results``, parallel HDF5)."""
