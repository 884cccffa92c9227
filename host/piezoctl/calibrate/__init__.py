"""``piezoctl calibrate``: from an unknown stage to a compensated one.

:mod:`.target` starts the virtual controller for ``--target sil``;
:mod:`.excitation` designs and plays the excitation through the firmware's
wave generator and recorder; :mod:`.pipeline` runs the seven steps; :mod:`.ilc` learns a periodic
reference's feedforward on the controller (iterative learning control);
:mod:`.coupling` the second axis and the cross-axis coupling;
:mod:`.report` writes ``report.html``.
"""
