# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Many runs at once: on threads (the kernel releases the interpreter lock), on forked
processes, on a Dask cluster."""
