# Lossless throughput against payload (data: throughput.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'throughput.svg'
set title 'Lossless throughput against payload'
set grid
set key outside right top
set datafile missing '?'
set logscale xy
set xtics ('64 B' 64, '1 MiB' 1048576)
set xlabel 'payload'
set ylabel 'messages per second'
plot 'throughput.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'SpscFloor', 'throughput.dat' index 1 using 1:2 with linespoints lw 2 pt 7 title 'SpscFloor256', 'throughput.dat' index 2 using 1:2 with linespoints lw 2 pt 7 title 'SpscInline', 'throughput.dat' index 3 using 1:2 with linespoints lw 2 pt 7 title 'SpscRecords', 'throughput.dat' index 4 using 1:2 with linespoints lw 2 pt 7 title 'SpscRecordsHeaders', 'throughput.dat' index 5 using 1:2 with linespoints lw 2 pt 7 title 'SpscShmLayout', 'throughput.dat' index 6 using 1:2 with linespoints lw 2 pt 7 title 'UnixSocket', 'throughput.dat' index 7 using 1:2 with linespoints lw 2 pt 7 title 'PosixMqueue', 'throughput.dat' index 8 using 1:2 with linespoints lw 2 pt 7 title 'Iceoryx', 'throughput.dat' index 9 using 1:2 with linespoints lw 2 pt 7 title 'Shm', 'throughput.dat' index 10 using 1:2 with linespoints lw 2 pt 7 title 'ShmLight', 'throughput.dat' index 11 using 1:2 with linespoints lw 2 pt 7 title 'ShmClock', 'throughput.dat' index 12 using 1:2 with linespoints lw 2 pt 7 title 'ShmBatch', 'throughput.dat' index 13 using 1:2 with linespoints lw 2 pt 7 title 'ShmViews', 'throughput.dat' index 14 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsShm', 'throughput.dat' index 15 using 1:2 with linespoints lw 2 pt 7 title 'FastDdsLoan'
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'throughput.png'
replot
