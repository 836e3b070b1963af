# One-way latency distribution at 64 B (data: latency-distribution-64.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'latency-distribution-64.svg'
set title 'One-way latency distribution at 64 B'
set grid
set key outside right top
set datafile missing '?'
set logscale y
set xtics ('p50' 0.301, 'p90' 1, 'p99' 2, 'p99.9' 3, 'max' 4)
set xrange [0.2:4.1]
set xlabel 'percentile'
set ylabel 'one-way latency (ns)'
plot 'latency-distribution-64.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'Floor', 'latency-distribution-64.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'UnixSocket', 'latency-distribution-64.dat' index 2 using 1:2 with linespoints lw 2 pt 7 title 'PosixMqueue', 'latency-distribution-64.dat' index 3 using 1:2 with linespoints lw 2 pt 7 title 'Iceoryx', 'latency-distribution-64.dat' index 4 using 1:2 with linespoints lw 2 pt 7 title 'Shm', 'latency-distribution-64.dat' index 5 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsShm', 'latency-distribution-64.dat' index 6 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsLoan'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'latency-distribution-64.png'
replot
