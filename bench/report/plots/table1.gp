# Table 1: ns per hop, chains of 100 services (data: table1.dat)
set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'
set output 'table1.svg'
set title 'Table 1: ns per hop, chains of 100 services'
set grid
set key outside right top
set datafile missing '?'
set logscale y
set ylabel 'ns per hop'
set style data histograms
set style histogram clustered gap 1
set style fill solid 0.85 border -1
set xtics rotate by -25
plot 'table1.dat' using 2:xtic(1) title columnheader(2), 'table1.dat' using 3 title columnheader(3), 'table1.dat' using 4 title columnheader(4), 'table1.dat' using 5 title columnheader(5), 'table1.dat' using 6 title columnheader(6), 'table1.dat' using 7 title columnheader(7)
set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'
set output 'table1.png'
replot
