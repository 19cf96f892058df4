/*  tls_direct_write(+TlsOut, +PlainIn, +PlainOut): the TLS records of a
    connection negotiated by library(ssl) go straight to its socket.
    tls_write_bio(+TlsOut, +PlainIn, +PlainOut, -Kind): where they go now,
    `socket` (OpenSSL's socket BIO) or `other` (ssl4pl's stream BIO).

    library(ssl) (ssl4pl, SWI-Prolog 9.0.4) gives OpenSSL a write BIO
    that copies every encrypted record into the plain socket stream with
    Sfwrite(), SWI-Prolog's per-byte output path (about 8 ns a byte: 8 ms
    for the 1 MB frame of an agent carrying 100,000 floats, more than the
    whole plaintext hop). Its read BIO copies in bulk (Sread_pending) and
    is left alone. This predicate replaces the connection's write BIO by
    OpenSSL's own socket BIO on the same file descriptor: the same bytes
    reach the same socket, in one send(2) per record. The handshake, the
    certificate checks, the session, the stream TlsOut and closing it are
    library(ssl)'s as before; closing frees the new BIO, and the socket is
    closed by the plain stream as before (the BIO does not own it).

    ssl4pl does not export the connection's SSL object, so it is found in
    the private record behind TlsOut's handle, whose layout (9.0.x) is

        config, ssl, sread, swrite, dread, dwrite, ...

    It is used only if TlsOut's functions are ssl4pl's (they lie in
    ssl4pl.so: dladdr()), and that record's wire streams are exactly
    PlainIn and PlainOut and its data write stream is TlsOut itself; any
    other stream or layout fails these checks and the predicate fails,
    leaving the connection as it was (the caller then writes through ssl4pl's BIO, slower). OpenSSL
    is not linked at build time: its two functions are taken from the
    libssl that ssl4pl has already loaded into the process, so building
    needs no OpenSSL headers, and without ssl4pl loaded this fails too.
*/
#define _GNU_SOURCE			/* dladdr() */
#include <SWI-Stream.h>
#include <SWI-Prolog.h>
#include <dlfcn.h>
#include <stddef.h>
#include <string.h>

typedef struct ssl_st SSL;
typedef struct bio_st BIO;

typedef struct			/* ssl4pl's PL_SSL_INSTANCE, 9.0.x */
{ void     *config;
  SSL      *ssl;
  IOSTREAM *sread;		/* wire streams */
  IOSTREAM *swrite;
  IOSTREAM *dread;		/* data streams */
  IOSTREAM *dwrite;
} ssl_instance;

#define OPENSSL_BIO_NOCLOSE 0x00

#define OPENSSL_BIO_TYPE_SOCKET (5|0x0400|0x0100)	/* BIO_TYPE_SOCKET */

static BIO  *(*new_socket_bio)(int sock, int close_flag);
static void  (*set0_wbio)(SSL *ssl, BIO *wbio);
static BIO  *(*get_wbio)(const SSL *ssl);
static int   (*bio_method_type)(const BIO *bio);

static int
openssl_functions(void)
{ static const char *names[] = { "libssl.so.3", "libssl.so.1.1", NULL };
  const char **n;

  if ( new_socket_bio && set0_wbio && get_wbio && bio_method_type )
    return TRUE;
  for(n = names; *n; n++)
  { void *h = dlopen(*n, RTLD_LAZY|RTLD_NOLOAD);	/* only one already loaded */

    if ( h )
    { new_socket_bio  = (BIO *(*)(int,int))dlsym(h, "BIO_new_socket");
      set0_wbio       = (void (*)(SSL*,BIO*))dlsym(h, "SSL_set0_wbio");
      get_wbio        = (BIO *(*)(const SSL*))dlsym(h, "SSL_get_wbio");
      bio_method_type = (int (*)(const BIO*))dlsym(h, "BIO_method_type");
      dlclose(h);			/* ssl4pl keeps it loaded */
      if ( new_socket_bio && set0_wbio && get_wbio && bio_method_type )
	return TRUE;
      new_socket_bio = NULL;
      set0_wbio = NULL;
      get_wbio = NULL;
      bio_method_type = NULL;
    }
  }
  return FALSE;
}

/*  Whether s is a stream of ssl4pl: its table of functions lies in
    ssl4pl.so. Only then is its handle ssl4pl's record (another stream's
    handle may be a file descriptor, not a pointer at all).
*/
static int
ssl4pl_stream(IOSTREAM *s)
{ Dl_info info;
  const char *base;

  if ( !s->functions || !dladdr((void *)s->functions, &info) || !info.dli_fname )
    return FALSE;
  base = strrchr(info.dli_fname, '/');
  base = base ? base+1 : info.dli_fname;
  return strcmp(base, "ssl4pl.so") == 0;
}

/*  The SSL object behind the TLS stream out, whose wire streams are in0
    and out0; NULL if out is no stream of ssl4pl or its record does not
    have the layout above.
*/
static SSL *
connection_ssl(IOSTREAM *out, IOSTREAM *in0, IOSTREAM *out0)
{ ssl_instance *inst;

  if ( !ssl4pl_stream(out) || !(inst = out->handle) )
    return NULL;
  if ( inst->sread == in0 && inst->swrite == out0 && inst->dwrite == out )
    return inst->ssl;
  return NULL;
}

typedef struct
{ IOSTREAM *out, *in0, *out0;
} streams;

static int
get_streams(term_t tls_out, term_t plain_in, term_t plain_out, streams *st)
{ st->out = st->in0 = st->out0 = NULL;
  return ( PL_get_stream(tls_out, &st->out, SIO_OUTPUT) &&
	   PL_get_stream(plain_in, &st->in0, SIO_INPUT) &&
	   PL_get_stream(plain_out, &st->out0, SIO_OUTPUT) );
}

static int
release_streams(streams *st, int rc)
{ if ( st->out0 && !PL_release_stream(st->out0) ) rc = FALSE;
  if ( st->in0  && !PL_release_stream(st->in0) )  rc = FALSE;
  if ( st->out  && !PL_release_stream(st->out) )  rc = FALSE;
  return rc;
}

static foreign_t
tls_direct_write(term_t tls_out, term_t plain_in, term_t plain_out)
{ streams st;
  int rc = FALSE;

  if ( get_streams(tls_out, plain_in, plain_out, &st) && openssl_functions() )
  { SSL *ssl = connection_ssl(st.out, st.in0, st.out0);
    int fd;

    if ( ssl && (fd = Sfileno(st.out0)) >= 0 &&
	 Sflush(st.out) == 0 && Sflush(st.out0) == 0 )
    { BIO *bio = (*new_socket_bio)(fd, OPENSSL_BIO_NOCLOSE);

      if ( bio )
      { (*set0_wbio)(ssl, bio);		/* frees ssl4pl's write BIO */
	rc = TRUE;
      }
    }
  }
  return release_streams(&st, rc);
}

static foreign_t
tls_write_bio(term_t tls_out, term_t plain_in, term_t plain_out, term_t kind)
{ streams st;
  int rc = FALSE;

  if ( get_streams(tls_out, plain_in, plain_out, &st) && openssl_functions() )
  { SSL *ssl = connection_ssl(st.out, st.in0, st.out0);
    BIO *bio;

    if ( ssl && (bio = (*get_wbio)(ssl)) )
      rc = PL_unify_atom_chars(kind,
			       (*bio_method_type)(bio) == OPENSSL_BIO_TYPE_SOCKET
				 ? "socket" : "other");
  }
  return release_streams(&st, rc);
}

install_t
install_tls_direct(void)
{ PL_register_foreign_in_module("tls", "tls_direct_write", 3, tls_direct_write, 0);
  PL_register_foreign_in_module("tls", "tls_write_bio", 4, tls_write_bio, 0);
}
