"""The contract files: angles CSV (``angles``), stations TOML (``stations``), trajectory CSV
(``trajectory``), and ``files``: TOML/CSV readers with one-line errors and the one atomic
writer (``write_atomic``).
"""
