"""Helpers shared by the pages, benchmarks and commands of :mod:`nbrdf_tools`."""
