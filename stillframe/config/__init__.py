"""Scene configuration: the declared keys with their checks, loading and overrides."""
