"""What runs leave: records, the comparison and its verdicts, summaries, exports and reference sets."""
