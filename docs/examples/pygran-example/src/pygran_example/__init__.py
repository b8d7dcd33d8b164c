"""An example third-party PyGran plugin (see the user guide, "Writing a plugin")."""
