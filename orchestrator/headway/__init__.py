"""Headway and capacity: blocking-time theory, co-simulated headway search, timetable compression."""
