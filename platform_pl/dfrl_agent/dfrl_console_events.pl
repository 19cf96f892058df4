:- module(dfrl_console_events,
          [ accept_log/1,               % +File
            dfrl_log/3,                 % +Platform, +Link, +Entry
            dfrl_driver/3,              % +Platform, +Link, +Message
            emit/1,                     % +Dict
            error_text/2,               % +Error, -Text
            request_ref/1,              % +Ref
            key/3,                      % +Key, +Dict, -Value
            text_atom/2,                % +Text, -Atom
            text_string/2,              % +Text, -String
            address/2                   % +Pair, -Address
          ]).
:- use_module('../messages', [platform_event/1]).
:- autoload(library(http/json), [json_write_dict/3, atom_json_dict/3]).
:- autoload(library(error), [must_be/2, domain_error/2, type_error/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [maplist/2]).

:- dynamic log_file/1.          % File: a launched agent may post lines for it

/** <module> What peers post to the console node, and its output

The platform event dfrl_log/3 of the console node (dfrl_console.pl):
an agent launched from the console, wherever it is, posts the lines of
its round log here, and they are appended to the file its launch
named, if the console accepted that file (accept_log/1, at launch).
Joins travel through the platform: this node declares the platform event
dfrl_console_events:dfrl_driver/3. A peer posts
`[dfrl_driver, platform, (H,P), Message]`,
(H,P) being the peer's own console node, with Message one of
`join(Request, SpecJSON, Iterations)`, `reply(Request, ResultJSON)`
(the JSON objects as strings) or `program(Name, Text)` (both strings).
The node prints them as event lines for its driver:

    {"event":"join_request","request":R,"robot":Spec,"iterations":N,"from":[H,P]}
    {"event":"reply","request":R,"result":Result,"from":[H,P]}
    {"event":"program","name":N,"text":T,"from":[H,P]}

and a message it cannot read as `{"event":"bad_message","error":...}`.

And the console's output: emit/1 writes one JSON object a line, under
one mutex, whole, and flushed.
*/

:- initialization(platform_event(dfrl_console_events:dfrl_log/3)).
:- initialization(platform_event(dfrl_console_events:dfrl_driver/3)).

%!  accept_log(+File) is det.
%
%   Agents may post lines for File.

accept_log(File) :-
    (   log_file(File) -> true ; assertz(log_file(File)) ).

%!  dfrl_log(+Platform, +Link, +Entry) is det.
%
%   Platform event: an agent launched from this console, wherever it is,
%   posts entry(File, Line), one line of its round log, or (from the
%   outbox of its node, log_outbox.pl) entries(Entries), File-Line pairs
%   in order; each line is appended to its File on this host, a batch in
%   one go. Only files named by a launch of this console are written;
%   anything else is reported as an event and dropped (a batch whole).

dfrl_log(platform, _Link, entry(File, Line)) :-
    log_lines_ok([File-Line]),
    !,
    append_log_lines([File-Line]).
dfrl_log(platform, _Link, entries(Entries)) :-
    is_list(Entries),
    log_lines_ok(Entries),
    !,
    append_log_lines(Entries).
dfrl_log(platform, Link, Entry) :-
    format(string(M), '~q', [Entry]),
    format(string(From), '~w', [Link]),
    emit(_{event:bad_message, message:M, error:"not a round-log line of an agent launched here",
           from:From}).

log_lines_ok(Entries) :-
    forall(member(E, Entries),
           (   nonvar(E), E = File-Line,
               atom(File), log_file(File),
               string(Line), \+ sub_string(Line, _, _, _, "\n")
           )).

append_log_lines(Entries) :-
    with_mutex(dfrl_console_log, append_runs(Entries)).

%   Consecutive lines for one file are written with one open.
append_runs([]).
append_runs([File-Line|Entries]) :-
    same_file(Entries, File, Lines, Rest),
    setup_call_cleanup(open(File, append, Out, [encoding(utf8)]),
                       forall(member(L, [Line|Lines]), format(Out, "~s~n", [L])),
                       close(Out)),
    append_runs(Rest).

same_file([File-Line|Entries], File, [Line|Lines], Rest) :-
    !,
    same_file(Entries, File, Lines, Rest).
same_file(Entries, _, [], Entries).

%!  emit(+Dict) is det.
%
%   Write Dict to the console's output, one whole line per JSON object;
%   replies (main thread) and events (message threads) may be written at
%   the same time.

emit(Dict) :-
    with_mutex(dfrl_console_output,
               ( json_write_dict(user_output, Dict, [width(0)]),
                 nl(user_output),
                 flush_output(user_output) )).

%!  dfrl_driver(+Platform, +Link, +Message) is det.
%
%   Platform event: a peer console (at Link) asks this node's driver to
%   add a robot, or answers such a request; printed as an event line.

dfrl_driver(platform, Link, Message) :-
    catch(driver_event(Link, Message, Event), E, true),
    (   var(E)
    ->  emit(Event)
    ;   error_text(E, Text),
        format(string(M), '~q', [Message]),
        emit(_{event:bad_message, message:M, error:Text})
    ).

driver_event(Link, join(R, SpecText, It), Event) :-
    !,
    link_pair(Link, From),
    request_ref(R),
    json_object(SpecText, Spec),
    (   It == null -> true ; must_be(nonneg, It) ),
    Event = _{event:join_request, request:R, robot:Spec, iterations:It, from:From}.
driver_event(Link, reply(R, ResultText), Event) :-
    !,
    link_pair(Link, From),
    request_ref(R),
    json_object(ResultText, Result),
    Event = _{event:reply, request:R, result:Result, from:From}.
driver_event(Link, program(Name, Text), Event) :-
    !,
    link_pair(Link, From),
    must_be(string, Name),
    must_be(string, Text),
    Event = _{event:program, name:Name, text:Text, from:From}.
driver_event(_, Message, _) :-
    domain_error(dfrl_driver_message, Message).

link_pair((H, P), [H, P]) :-
    atomic(H), integer(P),
    !.
link_pair(Link, _) :-
    type_error(link, Link).

json_object(Text, Dict) :-
    must_be(string, Text),
    atom_json_dict(Text, Dict, []),
    must_be(dict, Dict).

%!  request_ref(+Ref) is det.
%
%   @error type_error(request_id, Ref) unless Ref is a string or number.

request_ref(R) :-
    (   ( string(R) ; number(R) )
    ->  true
    ;   type_error(request_id, R)
    ).

%!  error_text(+Error, -Text) is det.
%
%   Text says what Error is, for a reply or an event.

error_text(failed(_), "the request failed") :- !.
error_text(E, Text) :-
    (   catch(message_to_string(E, Text0), _, fail)
    ->  Text = Text0
    ;   format(string(Text), '~p', [E])
    ).

		 /*******************************
		 *     READING JSON REQUESTS	*
		 *******************************/

%!  key(+Key, +Dict, -Value) is det.
%
%   @error existence_error(key, Key, Dict) if Dict has no Key.

key(Key, Dict, Value) :-
    (   get_dict(Key, Dict, Value)
    ->  true
    ;   throw(error(existence_error(key, Key, Dict), _))
    ).

%!  address(+Pair, -Address) is det.
%
%   Address is Host:Port of a JSON pair [Host, Port].

address([H0, P], H:P) :-
    !,
    text_atom(H0, H),
    must_be(integer, P).
address(A, _) :-
    type_error(address_pair, A).

%!  text_atom(+Text, -Atom) is det.
%!  text_string(+Text, -String) is det.
%
%   Text (an atom or string) as an atom, or as a string.
%
%   @error type_error(text, Text)

text_atom(X, A) :-
    (   atom(X) -> A = X
    ;   string(X) -> atom_string(A, X)
    ;   type_error(text, X)
    ).

text_string(X, S) :-
    (   string(X) -> S = X
    ;   atom(X) -> atom_string(X, S)
    ;   type_error(text, X)
    ).
