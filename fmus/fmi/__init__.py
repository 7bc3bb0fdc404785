"""FMI facade plumbing (the only part of ``fmus`` that imports pythonfmu): the slave base
class with its flat value stores, port declarations and the unit definitions written into
every modelDescription."""
