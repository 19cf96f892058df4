/*  plunit tests of the buffers of the platform's connections (transport.pl,
    node_connection.pl, tls.pl): a large frame moves through 64 KiB
    buffers once the peer is authenticated, an unauthenticated connection
    keeps the default 4 KiB.
    Run: swipl -g run_tests -t halt test_transport.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/transport').
:- use_module('../../platform_pl/node_ctx', [ctx_input/2]).
:- use_module(library(plunit)).

:- multifile node:platform_request/4.

%   A request of these tests only: the size of the input buffer of the
%   connection it arrives on, as the node's worker sees it.
node:platform_request(test_input_buffer, Ctx, ok(Size), true) :-
    ctx_input(Ctx, In),
    stream_property(In, buffer_size(Size)).

:- begin_tests(connection_buffers).

%   The client writes a frame through a 64 KiB buffer; the control is its
%   input, which keeps SWI-Prolog's default.
test(client_output_buffer, [cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    node_property(N, address(Address)),
    transport_open(Address, Conn, []),
    Conn = conn(_, Pair, _, _, _),
    stream_pair(Pair, In, Out),
    stream_property(Out, buffer_size(OutSize)),
    stream_property(In, buffer_size(InSize)),
    transport_close(Conn),
    assertion(OutSize == 65536),
    assertion(InSize == 4096).

%   The node reads through 4 KiB until the peer proves a token, then
%   through 64 KiB; a large frame right after that is read whole.
test(server_input_buffer_grows_at_authentication, [cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    node_property(N, address(Address)),
    transport_open(Address, Conn, []),
    call_cleanup(
        ( transport_send(Conn, text, test_input_buffer),
          transport_receive(Conn, Before, []),
          transport_auth(Conn, [k], access),
          transport_send(Conn, text, test_input_buffer),
          transport_receive(Conn, After, []),
          numlist(1, 50000, Big),
          transport_send(Conn, binary, Big),     % 450 KB: an unknown request
          transport_receive(Conn, Unknown, []),
          transport_send(Conn, binary, ping),
          transport_receive(Conn, Pong, [])
        ),
        transport_close(Conn)),
    assertion(Before == ok(4096)),
    assertion(After == ok(65536)),
    assertion(Unknown = error(error(domain_error(platform_request, '[|]'/2), _))),
    assertion(Pong = ok(pong(_))).

:- end_tests(connection_buffers).
