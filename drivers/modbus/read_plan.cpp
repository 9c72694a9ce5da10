#include "drivers/modbus/read_plan.hpp"

#include <algorithm>
#include <string>

#include "drivers/driver.hpp"

namespace scp::drivers::modbus {

ReadPlan plan_reads(const ModbusSettings& settings, int max_gap) {
  if (const auto clash = find_overlap(settings)) {
    throw DriverError("driver.modbus." + std::string(clash->first.name) + " (" +
                      std::string(table_name(clash->first.table)) + " registers " +
                      std::to_string(clash->first.first) + "-" + std::to_string(clash->first.last) +
                      ") overlaps driver.modbus." + std::string(clash->second.name) + " (" +
                      std::to_string(clash->second.first) + "-" +
                      std::to_string(clash->second.last) + "): give each its own registers");
  }
  struct Item {
    std::size_t signal;
    Table table;
    int first;
    int count;
  };
  std::vector<Item> items;
  const auto sigs = signals_of(settings);
  for (std::size_t i = 0; i < kSignalCount; ++i) {
    if (sigs[i]->present) {
      items.push_back({i, sigs[i]->table, sigs[i]->address, register_count(sigs[i]->type)});
    }
  }
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
    return a.table != b.table ? a.table < b.table : a.first < b.first;
  });
  ReadPlan plan;
  for (const Item& item : items) {
    if (!plan.blocks.empty()) {
      ReadBlock& last = plan.blocks.back();
      const int end = last.address + last.count;  // one past the block's last register
      const int gap = item.first - end;
      const int merged = item.first + item.count - last.address;
      if (last.table == item.table && gap <= max_gap && merged <= kMaxRegistersPerRead) {
        last.count = std::max(last.count, merged);
        plan.slots[item.signal] = {static_cast<int>(plan.blocks.size() - 1),
                                   item.first - last.address};
        continue;
      }
    }
    plan.blocks.push_back({item.table, item.first, item.count});
    plan.slots[item.signal] = {static_cast<int>(plan.blocks.size() - 1), 0};
  }
  return plan;
}

}  // namespace scp::drivers::modbus
