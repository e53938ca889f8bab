//! The link protocol between the host tool and the board (filled by the
//! firmware work): postcard messages in COBS frames with a CRC.
