"""Wayline (route) files shared by every aircraft family: the KMZ/WPML reader (kmz.py) and writer
(writer.py). Sans-I/O."""
