// The report's plots: for each, a data file and a gnuplot script in
// plots/, rendered by gnuplot to SVG and PNG.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <vector>
#include <sstream>

#include "process.hpp"
#include "report.hpp"

namespace prime::tool::bench {

namespace {

struct Series {
  std::string title;
  std::vector<std::pair<double, double>> points;
};

// Terminal, output and the common look; `body` sets axes and plots; then
// the same again as PNG.
std::string script(const std::string& name, const std::string& title, const std::string& body) {
  std::ostringstream gp;
  gp << "# " << title << " (data: " << name << ".dat)\n"
     << "set terminal svg size 900,520 dynamic noenhanced font 'sans,11' background rgb 'white'\n"
     << "set output '" << name << ".svg'\n"
     << "set title '" << title << "'\nset grid\nset key outside right top\nset datafile missing '?'\n"
     << body << "set terminal pngcairo size 900,520 noenhanced font 'sans,10' background rgb 'white'\n"
     << "set output '" << name << ".png'\nreplot\n";
  return gp.str();
}

// Lines of (x, y) per series, log–log when asked: data blocks in one file.
std::string lines_plot(const std::filesystem::path& plots, const std::string& name, const std::vector<Series>& series,
                       const std::string& axes) {
  std::ofstream dat{plots / (name + ".dat")};
  std::ostringstream plot;
  plot << axes << "plot ";
  int index = 0;
  for (const auto& s : series) {
    if (s.points.empty()) continue;
    dat << "# " << s.title << '\n';
    for (const auto& [x, y] : s.points) dat << x << ' ' << y << '\n';
    dat << "\n\n";
    plot << (index ? ", " : "") << "'" << name << ".dat' index " << index << " using 1:2 with linespoints lw 2 pt 7 title '"
         << s.title << "'";
    ++index;
  }
  plot << '\n';
  return index == 0 ? "" : plot.str();
}

std::string payload_tics(const std::vector<std::int64_t>& payloads) {
  std::string tics = "set xtics (";
  for (std::size_t i = 0; i < payloads.size(); ++i)
    tics += (i ? ", " : "") + ("'" + size_text(payloads[i]) + "' " + std::to_string(payloads[i]));
  return tics + ")\n";
}

// `statistic` against payload for everyone measured in `scenario`.
std::vector<Series> by_payload(const Results& r, const std::string& scenario, const std::string& statistic) {
  std::vector<Series> out;
  for (const auto& who : r.who_in(scenario)) {
    Series s{who, {}};
    for (const auto payload : r.payloads_in(scenario))
      if (const auto v = r.find(who, scenario, payload, statistic)) s.points.emplace_back(payload, *v);
    out.push_back(std::move(s));
  }
  return out;
}

// Percentiles on a scale of nines: p50 at 0.3, p90 at 1, p99 at 2, p99.9 at 3, max at 4.
std::vector<Series> distribution(const Results& r, const std::string& scenario, std::int64_t payload) {
  const std::pair<const char*, double> kAt[] = {{"p50", -std::log10(0.5)}, {"p90", 1}, {"p99", 2}, {"p99.9", 3}, {"max", 4}};
  std::vector<Series> out;
  for (const auto& who : r.who_in(scenario)) {
    Series s{who, {}};
    for (const auto& [statistic, x] : kAt)
      if (const auto v = r.find(who, scenario, payload, statistic)) s.points.emplace_back(x, *v);
    if (s.points.size() > 1) out.push_back(std::move(s));
  }
  return out;
}

// Clustered bars: a row per label, a column per who.
std::string bars_plot(const std::filesystem::path& plots, const std::string& name,
                      const std::vector<std::pair<std::string, std::vector<std::optional<double>>>>& rows,
                      const std::vector<std::string>& who, const std::string& axes) {
  if (rows.empty() || who.empty()) return "";
  std::ofstream dat{plots / (name + ".dat")};
  dat << "label";
  for (const auto& w : who) dat << " \"" << w << '"';
  dat << '\n';
  for (const auto& [label, values] : rows) {
    dat << '"' << label << '"';
    for (const auto& v : values) {
      if (v) dat << ' ' << *v;
      else dat << " ?";
    }
    dat << '\n';
  }
  std::ostringstream plot;
  plot << axes
       << "set style data histograms\nset style histogram clustered gap 1\nset style fill solid 0.85 border -1\n"
          "set xtics rotate by -25\nplot ";
  for (std::size_t i = 0; i < who.size(); ++i)
    plot << (i ? ", " : "") << "'" << name << ".dat' using " << i + 2 << (i == 0 ? ":xtic(1)" : "") << " title columnheader("
         << i + 2 << ")";
  plot << '\n';
  return plot.str();
}

}  // namespace

std::vector<std::string> write_plots(const std::filesystem::path& dir, const Results& r, std::string& problem) {
  const auto plots = dir / "plots";
  std::filesystem::create_directories(plots);
  std::vector<std::pair<std::string, std::string>> scripts;  // name, script
  auto add = [&](const std::string& name, const std::string& title, const std::string& body) {
    if (body.empty()) return;
    std::ofstream{plots / (name + ".gp")} << script(name, title, body);
    scripts.emplace_back(name, title);
  };
  const auto tics = payload_tics(r.payloads_in("latency"));
  add("latency", "One-way latency (p50) against payload, busy readers",
      lines_plot(plots, "latency", by_payload(r, "latency", "p50"),
                 "set logscale xy\n" + tics + "set xlabel 'payload'\nset ylabel 'one-way latency, p50 (ns)'\n"));
  const std::string nines =
      "set logscale y\nset xtics ('p50' 0.301, 'p90' 1, 'p99' 2, 'p99.9' 3, 'max' 4)\nset xrange [0.2:4.1]\n"
      "set xlabel 'percentile'\nset ylabel 'one-way latency (ns)'\n";
  add("latency-distribution-64", "One-way latency distribution at 64 B",
      lines_plot(plots, "latency-distribution-64", distribution(r, "latency", 64), nines));
  add("latency-distribution-1MiB", "One-way latency distribution at 1 MiB",
      lines_plot(plots, "latency-distribution-1MiB", distribution(r, "latency", 1 << 20), nines));
  add("throughput", "Lossless throughput against payload",
      lines_plot(plots, "throughput", by_payload(r, "throughput", "rate"),
                 "set logscale xy\n" + payload_tics(r.payloads_in("throughput")) +
                     "set xlabel 'payload'\nset ylabel 'messages per second'\n"));
  add("service", "Service round trip (p50) against payload",
      lines_plot(plots, "service", by_payload(r, "round-trip", "p50"),
                 "set logscale xy\n" + payload_tics(r.payloads_in("round-trip")) +
                     "set xlabel 'payload'\nset ylabel 'round trip, p50 (ns)'\n"));

  // Fan-out and sleeping subscribers: p50 and p99 against the number of subscribers, or the rate.
  auto scenario_series = [&](const std::string& prefix, const std::string& unit_suffix) {
    std::vector<Series> out;
    for (const char* statistic : {"p50", "p99"}) {
      std::map<std::string, Series> by_who;
      for (const auto& f : r.figures) {
        if (!f.scenario.starts_with(prefix) || f.statistic != statistic) continue;
        const auto x = std::stod(f.scenario.substr(prefix.size(), f.scenario.size() - prefix.size() - unit_suffix.size()));
        auto& s = by_who[f.who];
        s.title = f.who + " " + statistic;
        s.points.emplace_back(x, f.value);
      }
      for (auto& [who, s] : by_who) {
        std::sort(s.points.begin(), s.points.end());
        out.push_back(std::move(s));
      }
    }
    return out;
  };
  add("fan-out", "Fan-out at 64 B: latency of the last subscriber",
      lines_plot(plots, "fan-out", scenario_series("fan-out-", ""),
                 "set logscale y\nset xtics (1, 2, 4)\nset xlabel 'subscriber processes'\nset ylabel 'latency (ns)'\n"));
  add("sleeping", "Sleeping subscribers: wake-up latency against the publishing rate",
      lines_plot(plots, "sleeping", scenario_series("sleeping-", "hz"),
                 "set logscale xy\nset xlabel 'rate (Hz)'\nset ylabel 'publish to receive (ns)'\n"));

  // The 1 kHz loop: the percentiles of each run's lateness and end to end,
  // idle and under load.
  for (const auto& [kind, title] : {std::pair{"lateness", "1 kHz loop: wake-up lateness"},
                                    std::pair{"e2e", "1 kHz loop: end to end, publish to the subscriber holding it"}}) {
    std::vector<Series> series;
    for (const auto& [load, text] : {std::pair{"idle", " idle"}, std::pair{"load", " under load"}})
      for (auto s : distribution(r, std::string{"loop-"} + kind + "-" + load, 0)) {
        s.title += text;
        series.push_back(std::move(s));
      }
    const std::string name = std::string{"loop-"} + kind;
    add(name, title,
        lines_plot(plots, name, series,
                   "set logscale y\nset xtics ('p50' 0.301, 'p90' 1, 'p99' 2, 'p99.9' 3, 'max' 4)\n"
                   "set xrange [0.2:4.1]\nset xlabel 'percentile'\nset ylabel '" +
                       std::string{kind} + " (ns)'\n"));
  }

  // Table 1 as bars: ns per hop, a cluster per payload and width.
  {
    std::vector<std::string> who;
    std::vector<std::pair<std::string, std::vector<std::optional<double>>>> rows;
    std::vector<std::string> scenarios;
    for (const auto& f : r.figures)
      if (f.scenario.starts_with("table1-") && std::find(scenarios.begin(), scenarios.end(), f.scenario) == scenarios.end())
        scenarios.push_back(f.scenario);
    for (const auto& s : scenarios)
      for (const auto& w : r.who_in(s))
        if (std::find(who.begin(), who.end(), w) == who.end() && !w.ends_with("_Inlined")) who.push_back(w);
    for (const auto& s : scenarios)
      for (const auto payload : r.payloads_in(s)) {
        std::vector<std::optional<double>> values;
        for (const auto& w : who) values.push_back(r.find(w, s, payload, "per hop"));
        rows.emplace_back(size_text(payload) + " x" + s.substr(7, s.size() - 11), std::move(values));
      }
    add("table1", "Table 1: ns per hop, chains of 100 services",
        bars_plot(plots, "table1", rows, who, "set logscale y\nset ylabel 'ns per hop'\n"));
  }
  // Optimus against hiredis: mean time per operation.
  {
    std::vector<std::pair<std::string, std::vector<std::optional<double>>>> rows;
    for (const auto& f : r.figures)
      if ((f.who == "Optimus" || f.who == "hiredis") && f.statistic == "mean" && f.payload == 0)
        rows.emplace_back(f.who + " " + f.scenario, std::vector<std::optional<double>>{f.value / 1000.0});
    add("optimus", "Optimus against bare hiredis (one redis-server, loopback)",
        bars_plot(plots, "optimus", rows, {"time per operation"}, "set ylabel 'µs'\nset yrange [0:*]\nset key off\n"));
  }

  std::vector<std::string> rendered;
  if (!on_path("gnuplot")) {
    problem = "gnuplot is not installed (Debian: gnuplot-nox): the data and scripts are in plots/";
    return rendered;
  }
  for (const auto& [name, title] : scripts) {
    const auto done = run_program({"/usr/bin/env", "gnuplot", "-e", "cd '" + plots.string() + "'", name + ".gp"},
                                  plots / "gnuplot.log", std::chrono::seconds{60});
    if (done.status == 0 && std::filesystem::exists(plots / (name + ".svg")) && std::filesystem::exists(plots / (name + ".png")))
      rendered.push_back(name);
    else
      problem += (problem.empty() ? "" : "; ") + name + ": gnuplot failed (see plots/gnuplot.log)";
  }
  return rendered;
}

}  // namespace prime::tool::bench
