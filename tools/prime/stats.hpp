#pragma once

// What `prime hz`, `bw` and `delay` compute over a window of samples.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <deque>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

namespace prime::tool {

// `v` with `digits` digits after the point.
inline std::string fixed(double v, int digits = 3) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << v;
  return out.str();
}

// A window of the last `size` values.
class Window {
 public:
  explicit Window(std::size_t size) : size_{size} {}
  void add(double v) {
    values_.push_back(v);
    if (values_.size() > size_) values_.pop_front();
  }
  [[nodiscard]] std::size_t count() const { return values_.size(); }
  [[nodiscard]] double mean() const {
    double sum = 0;
    for (double v : values_) sum += v;
    return values_.empty() ? 0 : sum / static_cast<double>(values_.size());
  }
  [[nodiscard]] double stddev() const {
    if (values_.size() < 2) return 0;
    const auto m = mean();
    double sum = 0;
    for (double v : values_) sum += (v - m) * (v - m);
    return std::sqrt(sum / static_cast<double>(values_.size() - 1));
  }
  [[nodiscard]] double min() const { return values_.empty() ? 0 : *std::min_element(values_.begin(), values_.end()); }
  [[nodiscard]] double max() const { return values_.empty() ? 0 : *std::max_element(values_.begin(), values_.end()); }
  // The value below which `fraction` of them lie.
  [[nodiscard]] double percentile(double fraction) const {
    if (values_.empty()) return 0;
    std::vector<double> sorted(values_.begin(), values_.end());
    std::sort(sorted.begin(), sorted.end());
    const auto at = static_cast<std::size_t>(fraction * static_cast<double>(sorted.size() - 1) + 0.5);
    return sorted[std::min(at, sorted.size() - 1)];
  }

 private:
  std::size_t size_;
  std::deque<double> values_;
};

}  // namespace prime::tool
