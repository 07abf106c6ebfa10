"""Evaluation scenes: :mod:`.veach` (Veach's multiple-importance-sampling plates, built in the
repository) and :mod:`.kitchen` (Bitterli's 'Country Kitchen' with materials replaced, read from
the shared data)."""
