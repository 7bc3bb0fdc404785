"""Line, rolling-stock and timetable files: the loader (``loader.py``), their JSON schemas
(``schemas/``) and the data shipped inside every FMU (``shipped/``). No FMI."""
