#include "scheduler.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace psf {

uint64_t parse_bytes(const std::string& text) {
  size_t i = 0;
  while (i < text.size() && (std::isdigit(static_cast<unsigned char>(text[i])) || text[i] == '.')) ++i;
  if (i == 0) throw std::invalid_argument("'" + text + "' is not a size (e.g. 256M, 2G)");
  double value = 0;
  size_t used = 0;
  try {
    value = std::stod(text.substr(0, i), &used);
  } catch (const std::exception&) {
  }
  if (used != i) throw std::invalid_argument("'" + text + "' is not a size (e.g. 256M, 2G)");
  std::string unit = text.substr(i);
  for (auto& c : unit) c = char(std::toupper(static_cast<unsigned char>(c)));
  // "M", "MB" and "MiB" all mean 2^20; a lone "B" means bytes.
  if (unit.size() > 2 && unit.compare(unit.size() - 2, 2, "IB") == 0) unit.erase(unit.size() - 2);
  else if (unit.size() > 1 && unit.back() == 'B') unit.pop_back();
  if (unit == "B") unit.clear();
  double scale = 1;
  if (unit == "K") scale = 1024.0;
  else if (unit == "M") scale = 1024.0 * 1024;
  else if (unit == "G") scale = 1024.0 * 1024 * 1024;
  else if (unit == "T") scale = 1024.0 * 1024 * 1024 * 1024;
  else if (!unit.empty()) throw std::invalid_argument("'" + text + "': unknown unit (use K, M, G or T)");
  double bytes = value * scale;
  if (!(bytes >= 1) || bytes > 1.8e19) throw std::invalid_argument("'" + text + "' is out of range");
  return uint64_t(bytes);
}

std::string format_bytes(uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double v = double(bytes);
  int u = 0;
  while (v >= 1024 && u < 4) {
    v /= 1024;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, u ? "%.2f %s" : "%.0f %s", v, units[u]);
  return buf;
}

BatchPlan plan_batch(const std::vector<BufferNeed>& needs, uint64_t fixed, uint64_t global_mem, uint64_t max_alloc,
                     uint64_t budget, int max_log2, int min_log2) {
  uint64_t limit = budget ? std::min(budget, global_mem) : global_mem;
  double per_path = 0, widest = 0;
  for (const auto& n : needs) {
    per_path += n.bytes_per_path;
    widest = std::max(widest, n.bytes_per_path);
  }
  for (int m = max_log2; m >= min_log2; --m) {
    double paths = std::ldexp(1.0, m);
    uint64_t bytes = uint64_t(std::ceil(per_path * paths));
    uint64_t largest = uint64_t(std::ceil(widest * paths));
    if (fixed + bytes <= limit && largest <= max_alloc) return {m, bytes, largest};
  }
  double paths = std::ldexp(1.0, min_log2);
  throw std::runtime_error("a batch of " + std::to_string(uint64_t(paths)) + " paths needs " +
                           format_bytes(uint64_t(per_path * paths) + fixed) + " but the limit is " +
                           format_bytes(limit) + (budget ? " (--memory-budget)" : " (device memory)"));
}

int default_batch_log2(uint64_t pixels) {
  int m = 20;
  while (m < 22 && (uint64_t(1) << m) < pixels * kDefaultBatchSpp) ++m;
  return m;
}

}  // namespace psf
