"""pygran-toy-twin: a test plugin."""
