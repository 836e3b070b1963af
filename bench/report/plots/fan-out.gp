# Fan-out at 64 B: latency of the last subscriber (data: fan-out.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'fan-out.svg'
set title 'Fan-out at 64 B: latency of the last subscriber'
set grid
set key outside right top
set datafile missing '?'
set logscale y
set xtics (1, 2, 4)
set xlabel 'subscriber processes'
set ylabel 'latency (ns)'
plot 'fan-out.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'Shm p50', 'fan-out.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'Shm p99'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'fan-out.png'
replot
