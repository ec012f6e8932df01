"""Pose optimisers behind one interface: ISA (default), APF, PF, FSA, ICP."""
