"""Readers and writers: mechanism files in, results out."""
