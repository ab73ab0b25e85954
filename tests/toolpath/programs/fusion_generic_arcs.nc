%
(1001)
(Machine)
(  vendor: Autodesk)
(  description: Generic 3-axis)
(T1  D=6. CR=0. - ZMIN=-1. - flat end mill)
G90 G94 G17
G21

(2D Contour1)
T1 M6
S10000 M3
G0 X50. Y-5.
Z5.
G1 Z-1. F300.
Y0. F800.
G3 X0. Y50.004 I-50. J0.
G2 X-5.001 Y55.002 I0.001 J5.002
G0 Z5.
M5
M30
%
