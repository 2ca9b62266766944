"""The sections of ``docs/results.md`` (``python -m training.results`` writes them all) and their Markdown templates."""
