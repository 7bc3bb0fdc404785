"""The train categories: which speed tables judge a train (the ``train_category`` parameters)
and which trains a line file's temporary restriction applies to. A leaf, so that the data
layer and the signalling library both read it without importing each other. No dependencies."""

TRAIN_CATEGORIES = ("passenger", "freight", "high_speed")
