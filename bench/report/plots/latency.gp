# One-way latency (p50) against payload, busy readers (data: latency.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'latency.svg'
set title 'One-way latency (p50) against payload, busy readers'
set grid
set key outside right top
set datafile missing '?'
set logscale xy
set xtics ('64 B' 64, '4 KiB' 4096, '64 KiB' 65536, '1 MiB' 1048576, '4 MiB' 4194304)
set xlabel 'payload'
set ylabel 'one-way latency, p50 (ns)'
plot 'latency.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'Floor', 'latency.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'UnixSocket', 'latency.dat' index 2 using 1:2 with linespoints lw 2 pt 7 title 'PosixMqueue', 'latency.dat' index 3 using 1:2 with linespoints lw 2 pt 7 title 'Iceoryx', 'latency.dat' index 4 using 1:2 with linespoints lw 2 pt 7 title 'Shm', 'latency.dat' index 5 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsShm', 'latency.dat' index 6 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsLoan'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'latency.png'
replot
