"""Speed benchmarks: rays per second against Mitsuba's built-in BSDFs, and scenes with many
materials (their figures are on docs/results/performance.md)."""
