// Plots of the command-line tools: curves drawn by /usr/bin/gnuplot into a PNG, with the data
// (<png>.dat) and the script (<png>.gp) kept beside it so that `cd <folder> && gnuplot <png>.gp`
// re-plots. No gnuplot, or a failing one: a warning; the tool's JSON is the result.
#pragma once
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "cellsight/common/file_io.hpp"

namespace cellsight_tools {

struct YAxis {
  std::string label;
  bool percent = false;  ///< 0…100 with ticks every 20
  bool log = false;      ///< logarithmic
};

/// A string literal of gnuplot (single quotes: only ' itself is doubled).
inline std::string gpQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

/// A word for /bin/sh (single quotes).
inline std::string shQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

inline const char* const kGnuplot = "/usr/bin/gnuplot";

/// Writes <png>.dat and <png>.gp (header, then `settings`, then `plot`) beside the PNG and runs
/// gnuplot: it writes <png>.tmp, renamed onto <png> when it succeeded. Without gnuplot, or when
/// it fails: a warning only.
inline void drawPlot(const std::string& path, const std::string& title, const std::string& data, const std::string& settings,
                     const std::string& plot_command) {
  namespace fs = std::filesystem;
  const fs::path png(path);
  const fs::path dir = png.has_parent_path() ? png.parent_path() : fs::path(".");
  const std::string base = png.filename().string();
  const std::string dat = base + ".dat", gp = base + ".gp", tmp = base + ".tmp";
  cellsight::writeFileAtomic((dir / dat).string(), data);
  std::ostringstream g;
  g << "# " << title << " (written by a cellsight tool)\n"
    << "# re-plot: cd <this folder> && gnuplot " << gp << "   (writes " << base << "; gnuplot -e \"out='other.png'\" "
    << gp << " writes other.png)\n"
    << "if (!exists(\"out\")) out = " << gpQuote(base) << "\n"
    << "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
    << "  set terminal pngcairo noenhanced size 900,560 font 'sans,10'\n"
    << "} else {\n"
    << "  set terminal png noenhanced size 900,560\n"
    << "}\n"
    << "set output out\n"
    << "set title " << gpQuote(title) << "\n"
    << settings << "plot " << plot_command << "\nset output\n";
  cellsight::writeFileAtomic((dir / gp).string(), g.str());

  const std::string command = "cd " + shQuote(dir.string()) + " && " + kGnuplot + " -e " + shQuote("out=" + gpQuote(tmp)) + " " +
                              shQuote(gp);
  auto warn = [&](const std::string& why) {
    std::cerr << "warning: " << path << ": plot not drawn: " << why << " (command: " << command << "); the data and the script are in "
              << (dir / dat).string() << " and " << (dir / gp).string() << "\n";
  };
  if (::access(kGnuplot, X_OK) != 0) {
    warn(std::string(kGnuplot) + " is missing (Debian package gnuplot-nox)");
    return;
  }
  std::error_code ec;
  const int status = std::system(command.c_str());
  if (status == -1 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    if (fs::is_regular_file(dir / tmp, ec)) fs::remove(dir / tmp, ec);
    warn("gnuplot failed (status " + std::to_string(status == -1 || !WIFEXITED(status) ? status : WEXITSTATUS(status)) + ")");
    return;
  }
  fs::rename(dir / tmp, png, ec);
  if (ec) {
    const std::string why = ec.message();
    if (fs::is_regular_file(dir / tmp, ec)) fs::remove(dir / tmp, ec);
    warn("cannot move " + (dir / tmp).string() + " onto it: " + why);
  }
}

/// One data row: the first column, then each series' value at i (NaN where it has none).
inline void dataRow(std::ostream& d, const std::string& first, size_t i,
                    const std::vector<std::pair<std::string, std::vector<double>>>& series) {
  d << first;
  for (const auto& s : series) {
    d << "\t";
    if (i < s.second.size()) d << s.second[i]; else d << "NaN";
  }
  d << "\n";
}

/// Curves (one per series) over x as a PNG drawn by gnuplot. Beside the
/// PNG stay the data (<png>.dat) and the script (<png>.gp), which reads the data by its file name
/// in the PNG's folder: `cd <folder> && gnuplot <png>.gp` re-plots.
inline void plotLines(const std::string& path, const std::string& title, const std::string& xlabel, const YAxis& y,
                      const std::vector<double>& x, const std::vector<std::pair<std::string, std::vector<double>>>& series) {
  if (path.empty() || x.empty()) return;
  const std::string dat = std::filesystem::path(path).filename().string() + ".dat";
  std::ostringstream d;
  d << "# " << title << "\n# column 1: " << xlabel << "; then " << y.label << " per series:";
  for (const auto& s : series) d << " " << s.first;
  d << "\n";
  d << std::setprecision(10);
  for (size_t i = 0; i < x.size(); ++i) {
    std::ostringstream xi;
    xi << std::setprecision(10) << x[i];
    dataRow(d, xi.str(), i, series);
  }
  std::ostringstream g;
  g << "set xlabel " << gpQuote(xlabel) << "\n"
    << "set ylabel " << gpQuote(y.label) << "\n"
    << (y.percent ? "set yrange [0:100]\nset ytics 0,20,100\n" : "")
    << (y.log ? "set logscale y\n" : "")
    << "set grid\n"
    << "set key outside right top\n"
    << "set datafile missing 'NaN'\n";
  std::ostringstream p;
  for (size_t k = 0; k < series.size(); ++k) {
    p << (k ? ", \\\n    " : "") << (k ? "''" : gpQuote(dat)) << " using 1:" << k + 2 << " with linespoints lw 2 pt 7 title "
      << gpQuote(series[k].first);
  }
  drawPlot(path, title, d.str(), g.str(), p.str());
}

/// Grouped bars: one group per category (x), one bar per series, as a PNG (same files as plotLines).
inline void plotBars(const std::string& path, const std::string& title, const YAxis& y, const std::vector<std::string>& categories,
                     const std::vector<std::pair<std::string, std::vector<double>>>& series) {
  if (path.empty() || categories.empty()) return;
  const std::string dat = std::filesystem::path(path).filename().string() + ".dat";
  std::ostringstream d;
  d << "# " << title << "\n# column 1: category; then " << y.label << " per series:";
  for (const auto& s : series) d << " " << s.first;
  d << "\n" << std::setprecision(10);
  for (size_t i = 0; i < categories.size(); ++i) {
    std::string c = categories[i];
    for (char& ch : c) if (ch == ' ' || ch == '\t') ch = '_';
    dataRow(d, c, i, series);
  }
  std::ostringstream g;
  g << "set ylabel " << gpQuote(y.label) << "\n"
    << (y.percent ? "set yrange [0:105]\nset ytics 0,20,100\n" : "set yrange [0:*]\n")
    << "set style data histograms\nset style histogram clustered gap 1\nset style fill solid 0.8 border -1\n"
    << "set boxwidth 0.9\nset xtics rotate by -25\nset grid ytics\nset key outside right top\n"
    << "set datafile missing 'NaN'\n";
  std::ostringstream p;
  for (size_t k = 0; k < series.size(); ++k) {
    p << (k ? ", \\\n    " : "") << (k ? "''" : gpQuote(dat)) << " using " << k + 2 << (k ? "" : ":xtic(1)") << " title "
      << gpQuote(series[k].first);
  }
  drawPlot(path, title, d.str(), g.str(), p.str());
}

}  // namespace cellsight_tools
