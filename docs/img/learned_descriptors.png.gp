# registration success (RANSAC, guided sampling): held-out laser views of our parts, and real scenes (written by a cellsight tool)
# re-plot: cd <this folder> && gnuplot learned_descriptors.png.gp   (writes learned_descriptors.png; gnuplot -e "out='other.png'" learned_descriptors.png.gp writes other.png)
if (!exists("out")) out = 'learned_descriptors.png'
if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {
  set terminal pngcairo noenhanced size 900,560 font 'sans,10'
} else {
  set terminal png noenhanced size 900,560
}
set output out
set title 'registration success (RANSAC, guided sampling): held-out laser views of our parts, and real scenes'
set ylabel 'success [%]'
set yrange [0:105]
set ytics 0,20,100
set style data histograms
set style histogram clustered gap 1
set style fill solid 0.8 border -1
set boxwidth 0.9
set xtics rotate by -25
set grid ytics
set key outside right top
set datafile missing 'NaN'
plot 'learned_descriptors.png.dat' using 2:xtic(1) title 'FPFH', \
    '' using 3 title 'learned (LRF)', \
    '' using 4 title 'learned (augmentation)', \
    '' using 5 title 'learned (augmentation) + multi-rotation'
set output
