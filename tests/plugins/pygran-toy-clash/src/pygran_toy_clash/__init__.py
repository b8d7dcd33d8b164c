"""pygran-toy-clash: a test plugin."""
