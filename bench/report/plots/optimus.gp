# Optimus against bare hiredis (one redis-server, loopback) (data: optimus.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'optimus.svg'
set title 'Optimus against bare hiredis (one redis-server, loopback)'
set grid
set key outside right top
set datafile missing '?'
set ylabel 'µs'
set yrange [0:*]
set key off
set style data histograms
set style histogram clustered gap 1
set style fill solid 0.85 border -1
set xtics rotate by -25
plot 'optimus.dat' using 2:xtic(1) title columnheader(2)
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'optimus.png'
replot
