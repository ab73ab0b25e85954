(greybench explain tests: the square and circle finishing contours of the 160 test piece only)
(tool T1: flat end mill D10 mm; allowance 0.5 mm; workpiece origin: centre of the base top face, z up)
G21 G90 G17 G94
T1 M6
S12000 M3
G0 X-65 Y70 Z2
G1 X-65 Y70 Z0 F1000
G3 X-55 Y60 I10 J0 F3000
G1 X55 Y60 Z0
G2 X60 Y55 I0 J-5
G1 X60 Y-55 Z0
G2 X55 Y-60 I-5 J0
G1 X-55 Y-60 Z0
G2 X-60 Y-55 I0 J5
G1 X-60 Y55 Z0
G2 X-55 Y60 I5 J0
G3 X-45 Y70 I0 J10
G0 X-45 Y70 Z8
G0 X-10 Y69.5 Z8
G1 X-10 Y69.5 Z6 F1000
G3 X0 Y59.5 I10 J0 F3000
G2 X0 Y59.5 I0 J-59.5
G3 X10 Y69.5 I0 J10
G0 X10 Y69.5 Z12
M5
M30
