# One-way latency distribution at 1 MiB (data: latency-distribution-1MiB.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'latency-distribution-1MiB.svg'
set title 'One-way latency distribution at 1 MiB'
set grid
set key outside right top
set datafile missing '?'
set logscale y
set xtics ('p50' 0.301, 'p90' 1, 'p99' 2, 'p99.9' 3, 'max' 4)
set xrange [0.2:4.1]
set xlabel 'percentile'
set ylabel 'one-way latency (ns)'
plot 'latency-distribution-1MiB.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'UnixSocket', 'latency-distribution-1MiB.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'Iceoryx', 'latency-distribution-1MiB.dat' index 2 using 1:2 with linespoints lw 2 pt 7 title 'Shm', 'latency-distribution-1MiB.dat' index 3 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsShm', 'latency-distribution-1MiB.dat' index 4 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsLoan'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'latency-distribution-1MiB.png'
replot
