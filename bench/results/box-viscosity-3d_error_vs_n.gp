set terminal pngcairo size 900,650 font ',11'
set output 'bench/results/box-viscosity-3d_error_vs_n.png'
set datafile separator ','
set logscale xy
set grid
set key outside right
set xlabel 'N (cells across the box / per unit length)'
set ylabel 'L1 error'
set title 'box-viscosity-3d: L1 error against N'
plot 'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity-3d' && strcol(2) eq 'uniform' ? $8 : 1/0):6 with linespoints title 'uniform', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity-3d' && strcol(2) eq 'affine 16/2' ? $8 : 1/0):6 with linespoints title 'affine 16/2', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity-3d' && strcol(2) eq 'quadratic 16/2' ? $8 : 1/0):6 with linespoints title 'quadratic 16/2', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity-3d' && strcol(2) eq 'quadratic 8/2' ? $8 : 1/0):6 with linespoints title 'quadratic 8/2'
