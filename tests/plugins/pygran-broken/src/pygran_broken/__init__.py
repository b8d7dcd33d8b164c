"""pygran-broken: a test plugin."""
