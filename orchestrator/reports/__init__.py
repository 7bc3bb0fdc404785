"""``railcosim report``: a finished run's pictures and its verdict table (report.py), read from
its folder (results.csv, summary.json, the system it ran)."""
