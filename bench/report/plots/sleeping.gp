# Sleeping subscribers: wake-up latency against the publishing rate (data: sleeping.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'sleeping.svg'
set title 'Sleeping subscribers: wake-up latency against the publishing rate'
set grid
set key outside right top
set datafile missing '?'
set logscale xy
set xlabel 'rate (Hz)'
set ylabel 'publish to receive (ns)'
plot 'sleeping.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'Shm p50', 'sleeping.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'Shm p99'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'sleeping.png'
replot
