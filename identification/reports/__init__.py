"""What a person reads of an identification: tables, figures and ``report.md``.

:mod:`~identification.reports.tables` prints ``rocketroll identify``'s tables,
:mod:`~identification.reports.report` writes the paper's figures and report of
an identification, :mod:`~identification.reports.fitreport` and
:mod:`~identification.reports.flightreport` a method's judged fit of a tunnel run
or a flight, and :mod:`~identification.reports.summary` what ``rocketroll info``
says of a recording.
"""
