/*  bulk_write_bytes(+Stream, +Bytes): Bytes in one call to Stream's own write.

    SWI-Prolog 9.0.4 writes a string to a stream one byte at a time
    (write/2, format/3 and Sfwrite() all go through the per-byte output
    path), about 8 ns a byte: 8 ms for the 1 MB body of a 100,000-float
    agent. This predicate flushes what Stream has buffered and then hands
    Bytes to the stream's write function (a socket's send loop, an SSL
    stream's SSL_write, a file's write) in as few calls as it takes, so
    the kernel or OpenSSL sees one large buffer (OpenSSL then fills whole
    16 KB records).

    Only for a stream whose encoding is octet (a binary stream), where
    the bytes written are exactly Bytes either way; on any other stream
    it fails, and the caller writes as before. Bytes is a string or atom
    whose code points are all below 256 (representation_error otherwise).
    A failed write raises the stream's I/O error, as write/2 would. The
    stream's byte and character counts, if it keeps them, are advanced.
*/
#include <SWI-Stream.h>
#include <SWI-Prolog.h>
#include <errno.h>

static foreign_t
bulk_write_bytes(term_t stream, term_t bytes)
{ IOSTREAM *s;
  size_t len, done = 0;
  char *data;
  int ok = TRUE;

  if ( !PL_get_nchars(bytes, &len, &data,
		      CVT_STRING|CVT_ATOM|REP_ISO_LATIN_1|CVT_EXCEPTION) )
    return FALSE;
  if ( !PL_get_stream(stream, &s, SIO_OUTPUT) )
    return FALSE;
  if ( s->encoding != ENC_OCTET || !s->functions || !s->functions->write )
  { PL_release_stream(s);
    return FALSE;
  }
  if ( Sflush(s) < 0 )
    return PL_release_stream(s);	/* raises the stream's error */

  while ( done < len )
  { ssize_t n = (*s->functions->write)(s->handle, data+done, len-done);

    if ( n < 0 )
    { if ( errno == EINTR )
      { if ( PL_handle_signals() < 0 )
	{ ok = FALSE;
	  break;
	}
	continue;
      }
      Sseterr(s, SIO_FERR, NULL);
      break;
    }
    if ( n == 0 )
    { Sseterr(s, SIO_FERR, "write returned 0");
      break;
    }
    done += (size_t)n;
  }
  if ( s->position )
  { s->position->byteno += (int64_t)done;
    s->position->charno += (int64_t)done;
  }
  if ( !PL_release_stream(s) )
    return FALSE;
  return ok;
}

install_t
install_bulk_write(void)
{ PL_register_foreign_in_module("bulk_write", "bulk_write_bytes", 2, bulk_write_bytes, 0);
}
