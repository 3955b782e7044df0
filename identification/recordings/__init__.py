"""Recordings: the roll data every method reads.

:mod:`~identification.recordings.recording` is format v1 (and 1.1 for flights):
its columns, its metadata and the checks a recording passes before anything
reads it; :mod:`~identification.recordings.importer` brings a user's foreign CSV
log (other units, other names, a flight computer's log) into it;
:mod:`~identification.recordings.flight` reads what a flight log says of its
flight (its Mach number, the pad's elevation, its mean airspeed).
"""
