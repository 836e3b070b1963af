// `prime hz`, `bw` and `delay`, whatever the medium.
#include "watch.hpp"

#include <algorithm>
#include <chrono>
#include <iostream>

#include "json.hpp"
#include "stats.hpp"

namespace prime::tool {

namespace {

using namespace std::chrono_literals;

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// What one of the commands keeps of the last --window samples, and prints.
class Figures {
 public:
  Figures(const Options& o, std::string command)
      : o_{o}, command_{std::move(command)}, values_{o.window}, times_{o.window} {}

  void add(const Arrival& sample, Clock::time_point now) {
    if (command_ == "hz") {
      if (last_) values_.add(seconds(now - *last_));
      last_ = now;
    } else if (command_ == "bw") {
      values_.add(static_cast<double>(sample.size));
      times_.add(seconds(now.time_since_epoch()));
    } else if (sample.stamp) {
      values_.add(seconds(now - *sample.stamp));
    }
  }

  void print() const {
    if (command_ == "hz") print_rate();
    else if (command_ == "bw") print_bandwidth();
    else print_delay();
  }

 private:
  void print_rate() const {
    if (values_.count() == 0) return;
    const auto rate = 1 / values_.mean();
    if (o_.json)
      std::cout << "{\"topic\":" << quote(o_.name) << ",\"rate\":" << fixed(rate) << ",\"min\":" << fixed(values_.min(), 6)
                << ",\"max\":" << fixed(values_.max(), 6) << ",\"stddev\":" << fixed(values_.stddev(), 6)
                << ",\"window\":" << values_.count() << "}" << std::endl;
    else
      std::cout << "average rate: " << fixed(rate) << "\n\tmin: " << fixed(values_.min(), 6) << "s max: "
                << fixed(values_.max(), 6) << "s std dev: " << fixed(values_.stddev(), 6)
                << "s window: " << values_.count() << std::endl;
  }
  void print_bandwidth() const {
    if (times_.count() < 2) return;
    const auto span = times_.max() - times_.min();
    const auto rate = span > 0 ? values_.mean() * static_cast<double>(times_.count() - 1) / span : 0;
    if (o_.json)
      std::cout << "{\"topic\":" << quote(o_.name) << ",\"bytes_per_second\":" << fixed(rate, 1)
                << ",\"mean_size\":" << fixed(values_.mean(), 1) << ",\"window\":" << times_.count() << "}" << std::endl;
    else
      std::cout << "average: " << fixed(rate / 1024, 2) << " KiB/s\n\tmean size: " << fixed(values_.mean(), 0)
                << " B min: " << values_.min() << " B max: " << values_.max() << " B window: " << times_.count()
                << std::endl;
  }
  void print_delay() const {
    if (values_.count() == 0) return;
    if (o_.json)
      std::cout << "{\"topic\":" << quote(o_.name) << ",\"mean\":" << fixed(values_.mean(), 6) << ",\"p50\":"
                << fixed(values_.percentile(0.5), 6) << ",\"p99\":" << fixed(values_.percentile(0.99), 6)
                << ",\"max\":" << fixed(values_.max(), 6) << ",\"window\":" << values_.count() << "}" << std::endl;
    else
      std::cout << "average delay: " << fixed(values_.mean(), 6) << "s\n\tp50: " << fixed(values_.percentile(0.5), 6)
                << "s p99: " << fixed(values_.percentile(0.99), 6) << "s max: " << fixed(values_.max(), 6)
                << "s window: " << values_.count() << std::endl;
  }

  const Options& o_;
  std::string command_;
  Window values_;  // hz: periods; bw: sizes; delay: ages
  Window times_;   // bw: when each came
  std::optional<Clock::time_point> last_;
};

}  // namespace

int watch(const Options& o, const std::string& command, const NextSample& next) {
  Figures figures{o, command};
  finish_on_ctrl_c();
  const auto start = Clock::now();
  const auto end = o.duration > 0 ? start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.duration))
                                  : Clock::time_point::max();
  auto next_report = start + 1s;
  std::size_t seen = 0, reported = 0;
  auto last_sample = start;
  while (!ctrl_c_pressed() && Clock::now() < end && (o.count == 0 || seen < o.count)) {
    const auto sample = next(std::min<Clock::duration>(100ms, end - Clock::now()));
    const auto now = Clock::now();
    if (sample) {
      ++seen;
      last_sample = now;
      figures.add(*sample, now);
    }
    if (now >= next_report) {
      if (seen > 0 && seen == reported) {
        const auto idle = fixed(seconds(now - last_sample), 1);
        std::cout << (o.json ? "{\"topic\":" + quote(o.name) + ",\"no_new_samples_for_s\":" + idle + "}"
                             : "no new samples for " + idle + " s")
                  << std::endl;
      } else {
        figures.print();
      }
      reported = seen;
      next_report = now + 1s;
    }
  }
  if (seen != reported) figures.print();  // what came since the last report
  return after_ctrl_c(o.count == 0 && o.duration == 0, seen > 0 ? int{kOk} : int{kNothing});
}

}  // namespace prime::tool
