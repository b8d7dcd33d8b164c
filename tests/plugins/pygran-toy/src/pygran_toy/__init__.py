"""pygran-toy: a test plugin."""
