"""railcosim FMUs: one folder per unit (model core + thin pythonfmu facade) and the shared libraries

Everything in this package is bundled into every FMU with identical content, so FMUs
loaded into one interpreter never see different versions of the same module (docs/architecture.md#build-pipeline-railcosim-build).
"""
