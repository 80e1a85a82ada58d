#pragma once
// Frames from a V4L2 device, a video file or an image folder (OpenCV's videoio / imgcodecs).
#include <opencv2/core.hpp>

#include <memory>
#include <string>
#include <vector>

namespace cpm::aruco {

class FrameSource
{
public:
    virtual ~FrameSource() = default;
    /// The next frame (grey), or an empty Mat at the end. Blocks until it is due.
    virtual cv::Mat next() = 0;
    /// What the last frame came from (the device, the video, the image file), for messages.
    virtual std::string current() const = 0;
};

/// Each throws cpm::Error naming the path when it cannot be opened or holds no frame.
std::unique_ptr<FrameSource> open_device(const std::string& path);
std::unique_ptr<FrameSource> open_video(const std::string& path);
std::unique_ptr<FrameSource> open_images(const std::string& folder, double fps);

}  // namespace cpm::aruco
