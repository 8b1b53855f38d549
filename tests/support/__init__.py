"""Helpers shared by the tests: processes and DDS domains, nodes, scenes, identification data."""
