"""Running chains: vmapped chunks with progress, sharding, saving and resuming."""
