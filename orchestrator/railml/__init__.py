"""railML 3.1/3.2 infrastructure to a line file and back (docs/railml.md)."""
