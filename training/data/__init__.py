"""Training data: dataset readers behind one registry (:mod:`.datasets`), windows and their cache (:mod:`.windows`),
batches of windows as the network takes them (:mod:`.batches`), tracker-like noise (:mod:`.augment`)."""
