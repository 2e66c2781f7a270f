"""URDF in and out: the reader (and writer) of robot description files, registered like a third party's."""
