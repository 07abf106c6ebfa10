"""One generator per page of ``docs/results/``, named after the page (``spectral_networks`` writes
``docs/results/spectral-networks.md``); each page opens with the command that regenerates it."""
