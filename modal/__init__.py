"""Modal engine: FRFs, coherence, damping, identification and mode shapes."""
