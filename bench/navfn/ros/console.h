// Stands in for roscpp's logging header so that navfn compiles without ROS: the macros do nothing.
// roscpp's header brings <algorithm> along, and navfn.cpp uses std::min / std::max through it.
#pragma once
#include <algorithm>
#define ROS_DEBUG(...) ((void)0)
#define ROS_INFO(...) ((void)0)
#define ROS_WARN(...) ((void)0)
#define ROS_ERROR(...) ((void)0)
