%
(TASCHE - Fräser Ø10 mm, Maße in mm)
(Werkstück: Aluminium … Spannung außen)
G21 G90 G17
G0 X0. Y0. Z5.
G1 Z-1. F200.
G1 X20. (Länge 20 mm)
G0 Z5.
M30
%
