"""The cab-signalling library shared by coder, receiver, ATP and the verdict: aspects and
their speeds, ALSN code tables, the digital systems (ALS-EN, FIRE_DQPSK: codes, modems,
message acceptance, redundancy). No FMI."""
