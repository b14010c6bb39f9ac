"""Foreign recordings into contract files, one package per source (``hive``).
"""
