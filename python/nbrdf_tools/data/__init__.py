"""Makers of data the project ships or tests with: the pretrained models the ``nbrdf`` command
embeds, and spectral RGL measurements made from RGB ones."""
