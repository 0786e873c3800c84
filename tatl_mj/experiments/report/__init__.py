"""What a reader sees of a run: tables, figures, credit maps and clips."""
