"""``piezoctl calibrate``: from an unknown stage to a compensated one.

:mod:`.target` starts the virtual controller for ``--target sil``;
:mod:`.excitation` designs and plays the excitation through the firmware's
wave generator and recorder; :mod:`.pipeline` runs the seven steps;
:mod:`.report` writes ``report.html``.
"""
