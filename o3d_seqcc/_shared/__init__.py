"""Small helpers every stage uses: argument checks, interrupts, executors, progress, the method registry,
lazy re-exports. Nothing here imports a stage."""
