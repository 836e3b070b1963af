# Service round trip (p50) against payload (data: service.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'service.svg'
set title 'Service round trip (p50) against payload'
set grid
set key outside right top
set datafile missing '?'
set logscale xy
set xtics ('64 B' 64, '4 KiB' 4096, '64 KiB' 65536, '1 MiB' 1048576)
set xlabel 'payload'
set ylabel 'round trip, p50 (ns)'
plot 'service.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'Iceoryx', 'service.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'ShmService', 'service.dat' index 2 using 1:2 with linespoints lw 2 pt 7 title 'ShmServicesLinked', 'service.dat' index 3 using 1:2 with linespoints lw 2 pt 7 title 'ShmServicesRouted'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'service.png'
replot
