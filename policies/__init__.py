"""Navigation policies behind one contract (see `policies.base`)."""
