# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The package's own plumbing, private: the numba cache kept fresh, progress bars, work cut into
slices, guarded text files."""
