//! Bounds-checked parsing of the MCAP records the reader handles itself (footer, summary,
//! message headers, schema and channel records). Every length is checked against the bytes
//! at hand, so a corrupt length is a parse failure (`None`), never a large allocation.

use super::reader::SchemaInfo;

/// The MCAP magic bytes, at the start and the end of a file.
pub(crate) const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Opcode and length of every record.
pub(crate) const RECORD_HEADER: u64 = 9;
/// Footer record (opcode, length, 20-byte body) and the end magic.
pub(crate) const FOOTER_AND_MAGIC: u64 = 9 + 20 + 8;
/// DataEnd record: opcode, length, CRC.
pub(crate) const DATA_END_RECORD: u64 = 9 + 4;
/// Message record header: channel id, sequence, log time, publish time.
pub(crate) const MESSAGE_HEADER: usize = 2 + 4 + 8 + 8;

/// Bounds-checked little-endian parsing of record bodies.
pub(crate) struct Cur<'a> {
    pub(crate) b: &'a [u8],
}

impl<'a> Cur<'a> {
    pub(crate) fn new(b: &'a [u8]) -> Self {
        Cur { b }
    }
    pub(crate) fn bytes(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.b.len() < n {
            return None;
        }
        let (head, rest) = self.b.split_at(n);
        self.b = rest;
        Some(head)
    }
    pub(crate) fn array<const N: usize>(&mut self) -> Option<[u8; N]> {
        self.bytes(N)?.try_into().ok()
    }
    pub(crate) fn u16(&mut self) -> Option<u16> {
        self.array().map(u16::from_le_bytes)
    }
    pub(crate) fn u32(&mut self) -> Option<u32> {
        self.array().map(u32::from_le_bytes)
    }
    pub(crate) fn u64(&mut self) -> Option<u64> {
        self.array().map(u64::from_le_bytes)
    }
    /// A `uint32` length followed by that many bytes.
    pub(crate) fn prefixed(&mut self) -> Option<&'a [u8]> {
        let n = usize::try_from(self.u32()?).ok()?;
        self.bytes(n)
    }
    pub(crate) fn string(&mut self) -> Option<&'a str> {
        std::str::from_utf8(self.prefixed()?).ok()
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MessageHeader {
    pub(crate) channel_id: u16,
    pub(crate) sequence: u32,
    pub(crate) log_time: u64,
    pub(crate) publish_time: u64,
}

pub(crate) fn parse_message_header(body: &[u8]) -> Option<MessageHeader> {
    let mut c = Cur::new(body.get(..MESSAGE_HEADER)?);
    Some(MessageHeader {
        channel_id: c.u16()?,
        sequence: c.u32()?,
        log_time: c.u64()?,
        publish_time: c.u64()?,
    })
}

pub(crate) fn parse_schema(body: &[u8]) -> Option<SchemaInfo> {
    let mut c = Cur::new(body);
    Some(SchemaInfo {
        id: c.u16()?,
        name: c.string()?.to_string(),
        encoding: c.string()?.to_string(),
        data: c.prefixed()?.to_vec(),
    })
}

pub(crate) struct RawChannel<'a> {
    pub(crate) id: u16,
    pub(crate) schema_id: u16,
    pub(crate) topic: &'a str,
    pub(crate) message_encoding: &'a str,
}

pub(crate) fn parse_channel(body: &[u8]) -> Option<RawChannel<'_>> {
    let mut c = Cur::new(body);
    let ch = RawChannel {
        id: c.u16()?,
        schema_id: c.u16()?,
        topic: c.string()?,
        message_encoding: c.string()?,
    };
    c.prefixed()?; // metadata
    Some(ch)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ChunkIdx {
    pub(crate) start_time: u64,
    pub(crate) end_time: u64,
    pub(crate) offset: u64,
    pub(crate) length: u64,
}

pub(crate) fn parse_chunk_index(body: &[u8]) -> Option<ChunkIdx> {
    let mut c = Cur::new(body);
    let idx = ChunkIdx {
        start_time: c.u64()?,
        end_time: c.u64()?,
        offset: c.u64()?,
        length: c.u64()?,
    };
    c.prefixed()?; // message index offsets
    c.u64()?; // message index length
    c.string()?; // compression
    c.u64()?; // compressed size
    c.u64()?; // uncompressed size
    Some(idx)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Statistics {
    pub(crate) message_count: u64,
    pub(crate) start_time: u64,
    pub(crate) end_time: u64,
}

pub(crate) fn parse_statistics(body: &[u8]) -> Option<Statistics> {
    let mut c = Cur::new(body);
    let message_count = c.u64()?;
    c.u16()?; // schema count
    c.u32()?; // channel count
    c.u32()?; // attachment count
    c.u32()?; // metadata count
    c.u32()?; // chunk count
    Some(Statistics {
        message_count,
        start_time: c.u64()?,
        end_time: c.u64()?,
    })
}
