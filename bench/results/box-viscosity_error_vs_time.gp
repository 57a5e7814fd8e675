set terminal pngcairo size 900,650 font ',11'
set output 'bench/results/box-viscosity_error_vs_time.png'
set datafile separator ','
set logscale xy
set grid
set key outside right
set xlabel 'wall time per step [s] (set-up + solve)'
set ylabel 'L1 error'
set title 'box-viscosity: L1 error against time'
plot 'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity' && strcol(2) eq 'uniform' ? $9 : 1/0):6 with linespoints title 'uniform', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity' && strcol(2) eq 'affine 16/2' ? $9 : 1/0):6 with linespoints title 'affine 16/2', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity' && strcol(2) eq 'quadratic 16/2' ? $9 : 1/0):6 with linespoints title 'quadratic 16/2', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity' && strcol(2) eq 'affine 32/4' ? $9 : 1/0):6 with linespoints title 'affine 32/4', \
     'bench/results/accuracy_time.csv' using (strcol(1) eq 'box-viscosity' && strcol(2) eq 'quadratic 32/4' ? $9 : 1/0):6 with linespoints title 'quadratic 32/4'
