:- module(tls,
          [ tls_check_dir/1,            % +Dir
            tls_accept/5,               % +Dir, +PlainPair, -Pair, -PeerName, +Options
            tls_connect/5,              % +Dir, +Address, +PlainPair, -Pair, +Options
            tls_direct_native/1         % -Boolean
          ]).
:- use_module(library(ssl),
              [ ssl_context/3, ssl_negotiate/5, certificate_field/2 ]).
:- use_module(platform_errors, [transport_error/2]).
:- use_module(native_library, [native_library_load/2]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(error), [must_be/2]).
:- use_module(library(option), [option/2, option/3]).
:- use_module(library(time), [call_with_time_limit/2]).
:- use_module(library(lists), [member/2]).
:- use_module(library(filesex), [directory_file_path/3]).
:- use_module(library(debug), [debug/3]).

/** <module> Mutual TLS between platform nodes

A node started with tls(Dir) (see node_start/3) speaks TLS (1.2 or
later) on every connection, as server and as client. Dir holds the
files `dfrl certs node NAME CA_DIR --out Dir` writes:

  | File       | What                                                   |
  |------------|--------------------------------------------------------|
  | `ca.crt`   | the project CA: a peer must present a certificate it signed |
  | `node.crt` | this node's certificate (CN = the node's name)         |
  | `node.key` | its private key                                        |

Both sides present their certificate and verify the other's by the CA's
signature only: a certificate the CA did not sign, or none, ends the
handshake. Host names are not checked against the address connected to
(a node's name is not its address); a node that restricts who may send
it agents or code lists peer names instead (tls_peers(Names)), read from
the verified certificate's common name (kept by the verify hook).

The handshake happens before the platform's hello, so the nonce, the
token proofs and every frame after them travel encrypted. On the server
it is bounded like a pre-authentication frame: the whole handshake must
complete within a deadline, and the connection counts as
unauthenticated meanwhile (evictable by the admission caps).

Contexts are made once per directory and role and reused; they are made
again when one of the files changes.
*/

:- dynamic
    context_cache/4,            % Role, Dir, Stamp, SSL
    direct/1.                   % Boolean: native/tls_direct.so loaded

:- initialization(( native_library_load(tls_direct, Loaded),
                    assertz(direct(Loaded)) ), now).

:- multifile prolog:error_message//1, prolog:message//1.

%!  tls_direct_native(-Boolean) is det.
%
%   Boolean is `true` if this process's TLS connections write their
%   records straight to the socket (native/tls_direct.c loaded, and no
%   connection refused by its checks), `false` if through library(ssl)'s
%   stream byte by byte.

tls_direct_native(B) :-
    (   direct(true),
        \+ direct(refused)
    ->  B = true
    ;   B = false
    ).

%!  tls_check_dir(+Dir) is det.
%
%   Check that Dir holds the TLS files of a node and that a context can
%   be made from them (certificate and key match).
%
%   @error existence_error(file, Path) for a missing file.
%   @error tls_error(Dir, Reason) if the files do not make a context.

tls_check_dir(Dir) :-
    must_be(text, Dir),
    forall(member(F, ['ca.crt', 'node.crt', 'node.key']),
           (   directory_file_path(Dir, F, Path),
               exists_file(Path)
           ->  true
           ;   directory_file_path(Dir, F, Path),
               throw(error(existence_error(file, Path),
                           context(tls/1, 'make it with dfrl certs node NAME CA_DIR --out DIR')))
           )),
    context(server, Dir, _),
    context(client, Dir, _).

%   The context for Role from Dir's files, cached while they are unchanged.
context(Role, Dir, SSL) :-
    files(Dir, CA, Cert, Key),
    maplist([F, T]>>( exists_file(F) -> time_file(F, T) ; T = missing ),
            [CA, Cert, Key], Stamp),
    (   context_cache(Role, Dir, Stamp, SSL0)
    ->  SSL = SSL0
    ;   catch(ssl_context(Role, SSL0,
                          [ certificate_file(Cert), key_file(Key),
                            cacerts([file(CA)]),
                            peer_cert(true),
                            cert_verify_hook(tls:ca_signed),
                            min_protocol_version(tlsv1_2),
                            close_parent(true)
                          ]),
              E, context_failed(Dir, E)),
        with_mutex(dfrl_tls,
                   ( retractall(context_cache(Role, Dir, _, _)),
                     assertz(context_cache(Role, Dir, Stamp, SSL0)) )),
        SSL = SSL0
    ).

files(Dir, CA, Cert, Key) :-
    directory_file_path(Dir, 'ca.crt', CA),
    directory_file_path(Dir, 'node.crt', Cert),
    directory_file_path(Dir, 'node.key', Key).

context_failed(Dir, error(ssl_error(_, _, _, Reason), _)) :-
    !,
    throw(error(tls_error(Dir, Reason), _)).
context_failed(_, E) :-
    throw(E).

%   The verify hook: accept a certificate only if OpenSSL verified it
%   against the CA (no hostname check is asked for: no host(_) option).
%   It runs in the negotiating thread, once per certificate of the
%   peer's chain; it keeps the common name of the peer's own (first)
%   certificate for tls_accept/5. (ssl_peer_certificate/2 is not used
%   for that: in SWI-Prolog 9.0 it answers, for every connection of a
%   context, the certificate of the first one.)
ca_signed(_SSL, _Problem, _All, First, Error) :-
    Error == verified,
    (   certificate_cn(First, Name)
    ->  nb_setval(dfrl_tls_peer, Name)
    ;   true
    ).

certificate_cn(Cert, Name) :-
    certificate_field(Cert, subject(Subject)),
    member(Key=Value, Subject),
    Key == 'CN',
    !,
    atom_string(Name, Value).

%!  tls_accept(+Dir, +PlainPair, -Pair, -PeerName, +Options) is det.
%
%   Run the server side of the handshake on PlainPair (a socket's stream
%   pair) and return the encrypted Pair (closing it closes PlainPair
%   too) and the common name of the client's verified certificate.
%   Options:
%
%     - deadline(+Sec)   the whole handshake must end within Sec
%
%   @error tls_error(Peer, Reason) if the handshake fails or is late
%   (the caller closes PlainPair).

tls_accept(Dir, Plain, Pair, Name, Options) :-
    option(deadline(Secs), Options, 5),
    context(server, Dir, SSL),
    stream_pair(Plain, In0, Out0),
    nb_setval(dfrl_tls_peer, none),
    catch(bounded(Secs, In0, ssl_negotiate(SSL, In0, Out0, In, Out)),
          E, handshake_failed(server, E)),
    tune_streams(In0, Out0, In, Out),
    stream_pair(Pair, In, Out),
    nb_getval(dfrl_tls_peer, Name0),
    nb_setval(dfrl_tls_peer, none),
    (   Name0 \== none
    ->  Name = Name0
    ;   close(Pair, [force(true)]),
        throw(error(tls_error(server, no_peer_name), _))
    ).

%   A handshake within Secs: call_with_time_limit/2, and each read of
%   the plain stream In0 bounded by Secs too, because in a process whose
%   Prolog runs without signals (a robot process: pyswip starts it with
%   --nosignals) the alarm cannot interrupt a read that waits for a
%   silent peer; In0's own timeout is put back afterwards.
bounded(Secs, In0, Goal) :-
    stream_property(In0, timeout(Before)),
    setup_call_cleanup(set_stream(In0, timeout(Secs)),
                       call_with_time_limit(Secs, Goal),
                       set_stream(In0, timeout(Before))).

handshake_failed(_, time_limit_exceeded) :-
    !,
    throw(error(tls_error(handshake, timeout), _)).
handshake_failed(_, error(timeout_error(read, _), _)) :-
    !,
    throw(error(tls_error(handshake, timeout), _)).
handshake_failed(_, error(ssl_error(_, _, _, Reason), _)) :-
    !,
    throw(error(tls_error(handshake, Reason), _)).
handshake_failed(_, E) :-
    throw(E).

%!  tls_connect(+Dir, +Address, +PlainPair, -Pair, +Options) is det.
%
%   Run the client side of the handshake with the node at Address,
%   presenting Dir's certificate and verifying the server's against
%   Dir's CA. Options: timeout(+Sec) for the whole handshake
%   (default 5).
%
%   @error transport_error(Address, tls(Reason)) if it fails (the caller
%   closes PlainPair).

tls_connect(Dir, Address, Plain, Pair, Options) :-
    option(timeout(Secs), Options, 5),
    context(client, Dir, SSL),
    stream_pair(Plain, In0, Out0),
    catch(bounded(Secs, In0, ssl_negotiate(SSL, In0, Out0, In, Out)),
          E, connect_failed(Address, E)),
    tune_streams(In0, Out0, In, Out),
    stream_pair(Pair, In, Out),
    debug(dfrl(tls), 'TLS to ~w established', [Address]).

%   Large frames in few records: what is written to the encrypted stream
%   Out goes to SSL_write/3 one buffer at a time, each a TLS record, so
%   its buffer is one full record (16 KiB, TLS's largest) instead of the
%   default 4 KiB (a frame's body goes to SSL_write/3 in one piece, see
%   bulk_write.pl). Neither stream below counts lines and columns (see
%   wire.pl). The records then go straight to the socket where
%   native/tls_direct.c is built (tls_direct_write/3: ssl4pl would copy
%   them into the socket's stream byte by byte); elsewhere through the
%   socket's stream, several records per send(2).
tune_streams(In0, Out0, In, Out) :-
    set_stream(In0, buffer_size(65536)),
    set_stream(In, buffer_size(65536)),
    set_stream(In0, record_position(false)),
    set_stream(Out0, record_position(false)),
    set_stream(Out0, buffer_size(65536)),
    set_stream(Out, buffer_size(16384)),
    (   direct(true)
    ->  (   tls_direct_write(Out, In0, Out0)
        ->  true
        ;   refused_once
        )
    ;   true
    ).

%   The library is built but its checks refused this connection (another
%   ssl4pl): said once per process, since every connection is refused.
refused_once :-
    (   direct(refused)
    ->  true
    ;   assertz(direct(refused)),
        print_message(warning, tls_direct_refused)
    ).

connect_failed(Address, time_limit_exceeded) :-
    !,
    transport_error(Address, tls(timeout)).
connect_failed(Address, error(timeout_error(read, _), _)) :-
    !,
    transport_error(Address, tls(timeout)).
connect_failed(Address, error(ssl_error(_, _, _, Reason), _)) :-
    !,
    transport_error(Address, tls(Reason)).
connect_failed(Address, error(io_error(_, _), _)) :-
    !,
    transport_error(Address, tls(closed)).
connect_failed(_, E) :-
    throw(E).

prolog:message(tls_direct_refused) -->
    [ 'TLS records go through library(ssl)\'s stream, byte by byte: ',
      'native/tls_direct.so does not recognise this library(ssl)' ].

prolog:error_message(tls_error(Where, Reason)) -->
    [ 'TLS failed (~w): ~w'-[Where, Reason] ].
