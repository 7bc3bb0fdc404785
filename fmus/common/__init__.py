"""FMU-side code shared by every unit: facade base, units, line/rolling-stock data, build."""
