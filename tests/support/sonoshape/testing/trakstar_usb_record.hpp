#pragma once
// The sysfs record of a trakSTAR on USB for umockdev_testbed_add_from_string (the format
// umockdev-record writes; its N: line makes the usbfs node): vendor 0x21e2, product 0x0001, bus 1
// device 2, one vendor-class interface with bulk OUT 0x02 and bulk IN 0x86.

namespace sonoshape::testing {

/// Sysfs path of the device the record adds.
inline constexpr const char* kTrakstarSysPath = "/sys/devices/pci0000:00/usb1/1-1";

inline constexpr const char* kTrakstarUsbRecord =
    "P: /devices/pci0000:00/usb1/1-1\n"
    "N: bus/usb/001/002\n"
    "E: DEVNAME=/dev/bus/usb/001/002\n"
    "E: DEVTYPE=usb_device\n"
    "E: SUBSYSTEM=usb\n"
    "E: BUSNUM=001\n"
    "E: DEVNUM=002\n"
    "E: PRODUCT=21e2/1/100\n"
    "A: busnum=1\\n\n"
    "A: devnum=2\\n\n"
    "A: idVendor=21e2\\n\n"
    "A: idProduct=0001\\n\n"
    "A: speed=12\\n\n"
    "A: bConfigurationValue=1\\n\n"
    "A: bNumConfigurations=1\\n\n"
    // device: USB 2.0, 64-byte EP0, vendor 0x21e2, product 0x0001, one configuration;
    // configuration 1 (32 bytes): interface 0 (vendor class, two endpoints), bulk OUT 0x02
    // and bulk IN 0x86 with 64-byte packets
    "H: descriptors=12010002000000"
    "40e2210100000100000001"
    "09022000010100"
    "8032"
    "0904000002ff000000"
    "07050202400000"
    "07058602400000\n";

}  // namespace sonoshape::testing
