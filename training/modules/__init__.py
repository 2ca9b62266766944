"""The network, in PyTorch: :mod:`.dgan` (encoders, graph attention, heads, the padded export form, the consensus)."""
