"""A plugin whose import fails, as one with a missing system library would."""

raise ImportError("libbroken.so.1: cannot open shared object file")
